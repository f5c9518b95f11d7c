"""The delayed Kalman filter's model and its compiled kernels (DESIGN.md §4).

State (normalised image coordinates, internal)::

    x = (x_n, y_n, rho, v_tE, v_tN, v_tU)

x_n = X/Z, y_n = Y/Z the target's normalised image point (pixels / f_px; paper eq. 3), rho = 1/Z
the inverse depth along the optical axis (1/m), v_t the target's velocity in ENU (m/s). It is
the authors' 8-state idea (relative position, relative velocity, image point) written in
inverse-depth form, so the image point stays a state the detector measures directly and the
target's velocity is a world-frame random walk: a static target is v_t = 0, a moving one is
whatever the image flow says it is.

Process (one control step dt, inputs held over the step: gyro omega_c in the camera frame,
vehicle velocity v_c in ENU, camera attitude R_WC). With s = (x_n, y_n, 1) = rho p_c and
u = R_WC^T (v_t - v_c) the target's velocity relative to the camera, in the camera frame::

    s' = s + dt (rho u - omega_c x s),   x_n' = s'_x / s'_z,  y_n' = s'_y / s'_z,  rho' = rho / s'_z

which is exact for the translation over the step (Cartesian Euler of a constant velocity) and
first order in the rotation; its image-point rate is the full interaction matrix L_s (paper
eq. 4): the rotational columns times omega_c plus the translational columns times u with
depth 1/rho. F is the exact Jacobian of that map. v_t is a random walk
(``target_accel_noise_m_s2``); small white noise on the image rate and on rho covers the
unmodelled (camera offset from the centre of mass, gyro noise).

Measurements: the image point (1.5 px), and, when the detection's blob is whole (not touching
the frame edge), its apparent radius r = sqrt(area / pi) ~ f R rho / sqrt(1 + x_n^2 + y_n^2 -
R^2 rho^2) for a sphere of known diameter 2R (``target_diameter_m``), with a loose relative
noise that covers a wrong diameter. The apparent size makes depth observable at once; the
vehicle's own acceleration along and across the line of sight makes it observable over time.
Without size the depth starts from ``init_range_m`` with a wide prior.


Compiled (``onboard.jit``): the buffer is a window of preallocated arrays (one row per
prediction: time, inputs, x, F, Q, P and whether x and P are held), and a prediction (with the
oldest rows leaving), a fusion with its replay, a covariance propagation and the update are
each one kernel over those arrays, compiled at import when the JIT is on and plain Python
otherwise. The kernels are the filter's only implementation; their readable statement is
:mod:`.dkf_reference`. Their scalar arithmetic is Python's, operation for operation; their
matrix products are numpy's expressions, which numba hands to OpenBLAS (scipy's build of it;
numpy calls its own build), and on the filter's shapes the two give numpy's numbers to the
bit (tests/test_dkf_kernels.py; ``a ** two`` with the exponent from the parameter array is
libm's pow as Python's ``a ** 2`` is, where a literal 2 would compile to a * a, which differs
in the last bit for ~1 in 1000 a).
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import kernel

_TIME_EPS_S = 1e-9
_N = 6  # state size
_MAX_ABS_N = 4.0  # |x_n| beyond this (~76 deg off axis): the track has left the view
_MIN_SZ = 0.2  # one step never shrinks the depth by more than 80 %
_CAPACITY = 256  # buffered entries before the window grows (0.6 s at 200 Hz is 120)

# The filter's constants as one array for the kernels (_PRM_* are its indices).
_PRM_Q_IMG, _PRM_Q_V, _PRM_Q_RHO_REL, _PRM_RHO_MAX, _PRM_R_POINT, _PRM_GATE2 = range(6)
_PRM_RADIUS, _PRM_F, _PRM_SIZE_VAR_PX, _PRM_SIZE_REL, _PRM_TWO = range(6, 11)
# _PRM_TWO holds 2.0: ``a ** two`` with the exponent unknown to the compiler is libm's pow,
# as Python's ``a ** 2`` is (pow(a, 2) and a * a differ in the last bit for ~1 in 1000 a;
# a literal exponent would be compiled to a * a)

# Buffer layout: one row per buffered prediction (a window [lo, hi) of preallocated arrays).
# U holds the inputs held over (previous entry, t]: the camera-frame angular rate w (rad/s,
# 3), the vehicle velocity v_c (ENU, m/s, 3) and the world -> camera rotation R_CW (9,
# row-major); X the state at t, F the first three rows of the transition from the previous
# entry's state (18, row-major; the rest is the identity), Q the process noise's diagonal, P
# the covariance at t once it has been propagated; HX / HP say whether X / P are held.
_U_W, _U_V, _U_R = 0, 3, 6


# numba types of the kernels' arguments: contiguous vector, matrix, the buffer's P (rows of 6x6),
# flags; scalars; any-layout vector and matrix (inputs as the caller gives them)
_V, _M, _PB, _FLAGS = "float64[::1]", "float64[:, ::1]", "float64[:, :, ::1]", "uint8[::1]"
_S, _I, _B, _VOID, _VA, _MA = "float64", "int64", "boolean", "void", "float64[:]", "float64[:, :]"
_WIN = "int64[::1]"  # the buffer's window [lo, hi)


def _sig(ret: str, *args: str) -> str:
    """A numba signature string: ``ret(args...)``."""
    return f"{ret}({', '.join(args)})"


@kernel(_sig(_B, _V))
def _valid(x):
    """Finite, in front of the camera and within ~76 degrees of the axis (x: 6 floats)."""
    return (
        abs(x[0]) < _MAX_ABS_N
        and abs(x[1]) < _MAX_ABS_N
        and x[2] > 0.0
        and math.isfinite(x[3] + x[4] + x[5])
    )


@kernel(_sig(_VOID, _V, _V, _S, _V, _V, _V, _V))
def _step_x(x, u, dt, prm, x1, F, Q):
    """Propagate x (6) by dt with inputs u (a U row) into x1 (6), F's first three rows (18)
    and Q's diagonal (6)."""
    xn, yn, rho, vE, vN, vU = x[0], x[1], x[2], x[3], x[4], x[5]
    wx, wy, wz = u[0], u[1], u[2]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = (
        u[6],
        u[7],
        u[8],
        u[9],
        u[10],
        u[11],
        u[12],
        u[13],
        u[14],
    )
    dE, dN, dU = vE - u[3], vN - u[4], vU - u[5]
    ux = r00 * dE + r01 * dN + r02 * dU
    uy = r10 * dE + r11 * dN + r12 * dU
    uz = r20 * dE + r21 * dN + r22 * dU
    sx = xn + dt * (rho * ux - wy + wz * yn)
    sy = yn + dt * (rho * uy - wz * xn + wx)
    sz = 1.0 + dt * (rho * uz - wx * yn + wy * xn)
    if sz < _MIN_SZ:
        sz = _MIN_SZ
    iz = 1.0 / sz
    x_1, y_1, rho1 = sx * iz, sy * iz, min(rho * iz, prm[_PRM_RHO_MAX])
    # exact Jacobian of the map: d(s_i/s_z) = (ds_i - (s_i/s_z) ds_z) / s_z
    a, b = dt * iz, dt * rho * iz
    F[0] = iz - x_1 * a * wy
    F[1] = a * (wz + x_1 * wx)
    F[2] = a * (ux - x_1 * uz)
    F[3] = b * (r00 - x_1 * r20)
    F[4] = b * (r01 - x_1 * r21)
    F[5] = b * (r02 - x_1 * r22)
    F[6] = -a * (wz + y_1 * wy)
    F[7] = iz + y_1 * a * wx
    F[8] = a * (uy - y_1 * uz)
    F[9] = b * (r10 - y_1 * r20)
    F[10] = b * (r11 - y_1 * r21)
    F[11] = b * (r12 - y_1 * r22)
    F[12] = -rho1 * a * wy
    F[13] = rho1 * a * wx
    F[14] = iz - rho1 * a * uz
    F[15] = -rho1 * b * r20
    F[16] = -rho1 * b * r21
    F[17] = -rho1 * b * r22
    qi, qv = prm[_PRM_Q_IMG] * dt, prm[_PRM_Q_V] * dt
    Q[0] = qi
    Q[1] = qi
    Q[2] = prm[_PRM_Q_RHO_REL] * rho1 * rho1 * dt
    Q[3] = qv
    Q[4] = qv
    Q[5] = qv
    x1[0], x1[1], x1[2], x1[3], x1[4], x1[5] = x_1, y_1, rho1, vE, vN, vU


@kernel(_sig(_M, _M, _V, _V))
def _propagate(P, F, Q):
    """F P F^T + Q (symmetric to rounding; symmetrised at every update), F given by its first
    three rows (the last three are the identity's)."""
    Fm = np.zeros((6, 6))
    for i in range(18):
        Fm[i // 6, i % 6] = F[i]
    Fm[3, 3] = Fm[4, 4] = Fm[5, 5] = 1.0
    P1 = Fm @ P @ Fm.T
    for i in range(6):
        P1[i, i] += Q[i]
    return P1


@kernel(_sig(_B, _V, _M, _S, _S, _S, _V, _V, _M))
def _update(x, P, z0, z1, r_px, prm, x_out, P_out):
    """Gated EKF update of (x, P) with the image point (z0, z1), then (sequentially,
    relinearised at the updated state) the apparent radius r_px (px; NaN: not usable) if
    within its own gate, into (x_out, P_out). Joseph form in closed form for the 2-D and the
    scalar measurement (equal to filterpy's ``update``; tested). False (outputs untouched)
    when the point is gated."""
    r = prm[_PRM_R_POINT]
    y0, y1 = z0 - x[0], z1 - x[1]
    s00, s01, s11 = P[0, 0] + r, P[0, 1], P[1, 1] + r
    det = s00 * s11 - s01 * s01
    if not det > 0.0:
        return False
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    d2 = y0 * (i00 * y0 + i01 * y1) + y1 * (i01 * y0 + i11 * y1)
    if not d2 <= prm[_PRM_GATE2]:
        return False
    S_inv = np.empty((2, 2))
    S_inv[0, 0], S_inv[0, 1], S_inv[1, 0], S_inv[1, 1] = i00, i01, i01, i11
    K = np.ascontiguousarray(P[:, :2]) @ S_inv
    y = np.empty(2)
    y[0], y[1] = y0, y1
    x = x + K @ y
    A = P - K @ np.ascontiguousarray(P[:2, :])  # (I - K H) P
    P = A - np.ascontiguousarray(A[:, :2]) @ K.T + r * (K @ K.T)
    if not math.isnan(r_px):
        two = prm[_PRM_TWO]
        xn, yn, rho = x[0], x[1], x[2]
        R, f = prm[_PRM_RADIUS], prm[_PRM_F]
        n2 = max(1.0 + xn * xn + yn * yn - (R * rho) ** two, 1e-6)
        d = f * R / (n2 * math.sqrt(n2))
        hs = np.zeros(6)
        hs[0], hs[1], hs[2] = -d * rho * xn, -d * rho * yn, d * (n2 + (R * rho) ** two)
        h = f * R * rho / math.sqrt(n2)
        var_s = prm[_PRM_SIZE_VAR_PX] + (prm[_PRM_SIZE_REL] * h) ** two
        ys = r_px - h
        Ph = P @ hs
        ss = hs @ Ph + var_s
        if ys * ys <= prm[_PRM_GATE2] * ss:
            k = Ph / ss
            x = x + k * ys
            A = P - np.outer(k, Ph)
            P = A - np.outer(A @ hs, k) + var_s * np.outer(k, k)
    x[2] = min(max(x[2], 1e-6), prm[_PRM_RHO_MAX])
    x_out[:] = x
    P_out[:, :] = 0.5 * (P + P.T)
    return True


@kernel(_sig(_I, _PB, _M, _M, _FLAGS, _FLAGS, _I, _I))
def _covariance(P, F, Q, HX, HP, lo, i):
    """P at buffer row i, propagated from the last row before it that holds one: 1 when
    held, 0 without a state at i, -1 when there is none to start from (cannot happen with a
    track), -2 when it turned non-finite (the track is to be dropped)."""
    if HP[i]:
        return 1
    if not HX[i]:
        return 0
    k = i
    while k > lo and not HP[k] and HX[k - 1]:
        k -= 1
    if not HP[k]:
        return -1
    for n in range(k + 1, i + 1):
        P[n] = _propagate(P[n - 1], F[n], Q[n])
        HP[n] = 1
    Pi = P[i]
    if not math.isfinite(Pi[0, 0] + Pi[1, 1] + Pi[2, 2] + Pi[3, 3] + Pi[4, 4] + Pi[5, 5]):
        return -2
    return 1


@kernel(_sig(_I, _V, _M, _M, _M, _M, _PB, _FLAGS, _FLAGS, _WIN, _I, _S, _S, _S, _S, _V))
def _fuse_latest(T, U, X, F, Q, P, HX, HP, win, j, t_c, z0, z1, r_px, prm):
    """Fuse a measurement (later than every stored one) captured at t_c inside buffer
    interval (j, j+1]: exact at j+1, then the linearised correction of the state carried to
    row hi - 1 through the buffered F (dx_k = F_k dx_{k-1}); the later covariances are
    propagated when next needed. 1: accepted; 0: gated; < 0: _covariance's failure."""
    hi = win[1]
    code = _covariance(P, F, Q, HX, HP, win[0], j)
    if code < 1:
        return code
    nxt = j + 1
    x, Fs, Qs = np.empty(6), np.empty(18), np.empty(6)
    _step_x(X[j], U[nxt], t_c - T[j], prm, x, Fs, Qs)
    P1 = _propagate(P[j], Fs, Qs)
    xu, Pu = np.empty(6), np.empty((6, 6))
    if not _update(x, P1, z0, z1, r_px, prm, xu, Pu):
        return 0
    _step_x(xu, U[nxt], T[nxt] - t_c, prm, x, Fs, Qs)  # F of the full step stays buffered
    P[nxt] = _propagate(Pu, Fs, Qs)
    HP[nxt] = 1
    b = X[nxt]
    d0, d1, d2, d3, d4, d5 = (
        x[0] - b[0],
        x[1] - b[1],
        x[2] - b[2],
        x[3] - b[3],
        x[4] - b[4],
        x[5] - b[5],
    )
    b[:] = x
    rho_max = prm[_PRM_RHO_MAX]
    for k in range(j + 2, hi):
        # dx_k = F_k dx_{k-1}: F's last three rows are the identity
        G = F[k]
        d0, d1, d2 = (
            G[0] * d0 + G[1] * d1 + G[2] * d2 + G[3] * d3 + G[4] * d4 + G[5] * d5,
            G[6] * d0 + G[7] * d1 + G[8] * d2 + G[9] * d3 + G[10] * d4 + G[11] * d5,
            G[12] * d0 + G[13] * d1 + G[14] * d2 + G[15] * d3 + G[16] * d4 + G[17] * d5,
        )
        e = X[k]
        e[0] = e[0] + d0
        e[1] = e[1] + d1
        e[2] = min(max(e[2] + d2, 1e-6), rho_max)
        e[3] = e[3] + d3
        e[4] = e[4] + d4
        e[5] = e[5] + d5
        HP[k] = 0
    return 1


@kernel(
    _sig(
        _B, _V, _M, _M, _M, _M, _PB, _FLAGS, _FLAGS, _I, _I, _V, _M, _S, _V, _M, _V, _I, _S, _V, _V
    )
)
def _replay(T, U, X, F, Q, PB, HX, HP, hi, j, x, P, t, mt, mz, mr, k, new_t_c, prm, last):
    """From state (x, P) at time t inside buffer interval j, re-run every later buffered
    step, fusing the stored measurements (capture times mt, points mz, radii mr) from index
    k on in capture order; writes every state back. last[0] is raised to the capture time of
    each accepted measurement. True when the one captured at new_t_c (NaN: none) was."""
    new_accepted = False
    xu, Pu = np.empty(6), np.empty((6, 6))
    x1, Fs, Qs = np.empty(6), np.empty(18), np.empty(6)
    for i in range(j + 1, hi):
        u = U[i]
        while k < mt.shape[0] and mt[k] <= T[i] + _TIME_EPS_S:
            _step_x(x, u, mt[k] - t, prm, x1, Fs, Qs)
            P = _propagate(P, Fs, Qs)
            x = x1.copy()
            t = mt[k]
            ok = _update(x, P, mz[k, 0], mz[k, 1], mr[k], prm, xu, Pu)
            if ok:
                x = xu.copy()
                P = Pu.copy()
                last[0] = max(last[0], mt[k])
            if mt[k] == new_t_c:
                new_accepted = ok
            k += 1
        _step_x(x, u, T[i] - t, prm, X[i], F[i], Q[i])
        P = _propagate(P, F[i], Q[i])
        x = X[i].copy()
        t = T[i]
        PB[i] = P
        HX[i] = 1
        HP[i] = 1
    return new_accepted


@kernel(_sig(_I, _V, _M, _M, _M, _M, _PB, _FLAGS, _FLAGS, _WIN, _B, _S, _S, _VA, _VA, _MA, _V, _V))
def _predict(T, U, X, F, Q, P, HX, HP, win, tracking, time_s, horizon, gyro, v_c, R_WC, R_CB, prm):
    """Append the prediction at time_s to the window win = [lo, hi): the inputs (gyro in the
    body frame, rad/s; vehicle velocity ENU, m/s, or empty: still; camera attitude camera ->
    ENU, or empty: level, R_CW = R_CB), a non-finite one replaced by the previous row's (the
    filter never sees NaN), and, when tracking, the state stepped from row hi - 1 with F and
    Q. Then the rows at or before ``horizon`` leave the window (but the last two), the oldest
    remaining one with its covariance propagated (it is where P is propagated from).
    1: stepped; 0: not tracking; -1: the step left the view or turned non-finite (nothing
    has left); -2: a covariance turned non-finite (the rows before it have left); on < 0 the
    track is to be dropped and the old rows removed by the caller."""
    lo, hi = win[0], win[1]
    u = U[hi]
    g0, g1, g2 = gyro[0], gyro[1], gyro[2]
    c = R_CB
    u[0] = c[0] * g0 + c[1] * g1 + c[2] * g2
    u[1] = c[3] * g0 + c[4] * g1 + c[5] * g2
    u[2] = c[6] * g0 + c[7] * g1 + c[8] * g2
    if v_c.shape[0] == 3:
        u[3], u[4], u[5] = v_c[0], v_c[1], v_c[2]
    else:
        u[3] = u[4] = u[5] = 0.0
    if R_WC.shape[0] == 3:
        for a in range(3):
            for b in range(3):
                u[6 + 3 * a + b] = R_WC[b, a]
    else:
        u[6:15] = R_CB
    has_prev = hi > lo
    for first, n in ((0, 3), (3, 3), (6, 9)):
        s = 0.0
        for m in range(first, first + n):
            s += u[m]
        if not math.isfinite(s):
            for m in range(first, first + n):
                if has_prev:
                    u[m] = U[hi - 1, m]
                elif first == 6:
                    u[m] = R_CB[m - 6]
                else:
                    u[m] = 0.0
    T[hi] = time_s
    HX[hi] = HP[hi] = 0
    win[1] = hi + 1
    code = 0
    if tracking:
        _step_x(X[hi - 1], u, time_s - T[hi - 1], prm, X[hi], F[hi], Q[hi])
        if not _valid(X[hi]):
            return -1
        HX[hi] = 1
        code = 1
    hi += 1
    while hi - lo > 2 and T[lo + 1] <= horizon:
        if not HP[lo + 1] and HX[lo + 1] and _covariance(P, F, Q, HX, HP, lo, lo + 1) < 0:
            return -2
        lo += 1
        win[0] = lo
    return code


@kernel(_sig(_I, _V, _I, _I, _S))
def _bisect_right(a, lo, hi, t):
    """The index in [lo, hi] where t would be inserted after its equals in the sorted a
    (Python's ``bisect.bisect_right``, the same comparisons)."""
    while lo < hi:
        mid = (lo + hi) // 2
        if t < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@kernel(_sig("UniTuple(float64, 14)", _V, _M, _M, _FLAGS, _WIN, _B, _S, _S, _S, _B, _S))
def _view(T, U, X, HX, win, tracking, last_accepted_s, lost_timeout_s, f, at_given, at_s):
    """A control tick's reads of the buffer in one call (compiled). The estimate at the newest
    row when it holds a state and ``tracking``: (1, its time, e (px), e's rate (px/s: the
    rotational plus translational flow of x with the row's inputs), the time since the last
    accepted detection, 1 if that is beyond ``lost_timeout_s`` else 0, the translational flow
    (px/s)), else 0 and nans; then the buffered image error at ``at_s`` if ``at_given`` and a
    row at that time holds a state: (1, e (px)), else (0, nan, nan); then the range along the
    LOS (m) from the mean (the estimate's; inf for rho <= 0), nan without one."""
    lo, hi = win[0], win[1]
    held = 0.0
    t = ex = ey = erx = ery = since = lost = trx = try_ = rng = math.nan
    if tracking and hi > lo and HX[hi - 1]:
        i = hi - 1
        xn, yn, rho, vE, vN, vU = X[i, 0], X[i, 1], X[i, 2], X[i, 3], X[i, 4], X[i, 5]
        wx, wy, wz = U[i, 0], U[i, 1], U[i, 2]
        dE, dN, dU = vE - U[i, 3], vN - U[i, 4], vU - U[i, 5]
        ux = U[i, 6] * dE + U[i, 7] * dN + U[i, 8] * dU
        uy = U[i, 9] * dE + U[i, 10] * dN + U[i, 11] * dU
        uz = U[i, 12] * dE + U[i, 13] * dN + U[i, 14] * dU
        rot0 = xn * yn * wx - (1.0 + xn * xn) * wy + yn * wz
        rot1 = (1.0 + yn * yn) * wx - xn * yn * wy - xn * wz
        tr0, tr1 = rho * (ux - xn * uz), rho * (uy - yn * uz)
        held = 1.0
        t = T[i]
        ex, ey = xn * f, yn * f
        erx, ery = (rot0 + tr0) * f, (rot1 + tr1) * f
        since = t - last_accepted_s
        lost = 1.0 if since > lost_timeout_s else 0.0
        trx, try_ = tr0 * f, tr1 * f
        rng = math.sqrt(1.0 + xn * xn + yn * yn) / rho if rho > 0.0 else math.inf
    at_held = 0.0
    pex = pey = math.nan
    if at_given:
        for k in range(hi - 1, lo - 1, -1):  # the newest rows first
            if abs(T[k] - at_s) < _TIME_EPS_S:
                if HX[k]:
                    at_held, pex, pey = 1.0, X[k, 0] * f, X[k, 1] * f
                break
            if T[k] < at_s:
                break
    return held, t, ex, ey, erx, ery, since, lost, trx, try_, at_held, pex, pey, rng
