"""Delayed Kalman filter (DKF) for the target's image point, depth and velocity (DESIGN.md §4).

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

Delay: every prediction is buffered as (time, inputs, x, F, Q) and, lazily, P. A detection
captured at t_c is fused at t_c: the filter takes the buffered state just before t_c,
propagates to t_c with the buffered inputs, updates (Joseph form in closed form, equal to
filterpy's ``update``), propagates to the next buffered time, and carries the correction of
the state forward to now through the buffered transition matrices: x_k += Phi_k dx with
Phi_k = F_k ... F_{j+2}, one 3x6 product in floats per buffered step (F's last three rows are
the identity). That is the replay of the linearised filter. The covariance is propagated only
when it is needed (the next fusion, the oldest entry leaving the buffer, a caller asking for
it): P_k = F_k P_{k-1} F_k^T + Q_k from the last entry that holds one, with the buffered F and
Q, which equals carrying dP forward as Phi_k dP Phi_k^T; a tick without a fusion does no 6x6
arithmetic, and every P is computed by the same steps whenever it is asked for, so a caller
that reads the covariance every tick (the simulator's recorded frames) flies bit for bit as
one that never does. A detection captured before one already fused (out of order) is fused by a full
replay in capture order (every step re-propagated with the buffered inputs). Every replayed
state is written back. The delay comes from timestamps only.

Compiled (``onboard.jit``): the buffer is a window of preallocated arrays (one row per
prediction: time, inputs, x, F, Q, P and whether x and P are held), and a prediction (with the
oldest rows leaving), a fusion with its replay, a covariance propagation and the update are
each one numba kernel over those arrays, compiled at import. The kernels are the filter's only
implementation (``PEREGRINE_JIT=0`` runs them as Python). Their scalar arithmetic is Python's,
operation for operation; their matrix products are numpy's expressions, which numba hands to
OpenBLAS (scipy's build of it; numpy calls its own build), and on the filter's shapes the two
give numpy's numbers to the bit
(tests/test_dkf_kernels.py compares every kernel with its Python source; ``a ** two`` with
the exponent from the parameter array is libm's pow as Python's ``a ** 2`` is, where a
literal 2 would compile to a * a, which differs in the last bit for ~1 in 1000 a).

Robustness: non-finite or out-of-view detections are refused, the point innovation is gated
(Mahalanobis, 2 dof) and the size innovation separately (1 dof), P is symmetrised at every
update, rho is kept in (0, 1/min_depth_m], and the track is dropped when the prediction leaves
the view by more than ~76 degrees or turns non-finite (the state at every step, the
covariance when it is propagated).

Re-started tracks: a detection after the track went stale (``lost_timeout_s``) starts a new
track at its image point, but with ``carry_max_s`` > 0 (the loop's gain ``t_carry``) and the
old track last confirmed less than that long ago, the new one keeps what the old one still
knows: the target velocity with its covariance grown by the random walk over the time without
measurements (P_vv + q_v dt I: exactly what the propagation does to it), and, when the old
track is still propagated and the detection falls inside its grown image gate, the depth and
the depth-velocity covariance too, the detection's apparent size fused into them. A velocity
vaguer than the first-detection prior (``init_target_speed_m_s``) is not carried.
"""

from __future__ import annotations

import bisect
import dataclasses
import enum
import math
from dataclasses import dataclass

import numpy as np

from ..camera_model import CameraModel
from ..datatypes import Detection
from ..jit import kernel

_TIME_EPS_S = 1e-9
_F64 = np.dtype(np.float64)  # the descriptor of ordinary float arrays
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
        var_s = prm[_PRM_SIZE_VAR_PX] + (prm[_PRM_SIZE_REL] * r_px) ** two
        ys = r_px - f * R * rho / math.sqrt(n2)
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


def _floats3(v) -> tuple[float, float, float]:
    """Three floats from a 3-vector (ndarray or sequence)."""
    if type(v) is np.ndarray and v.dtype == _F64 and v.shape == (3,):
        return tuple(v.tolist())
    out = v.tolist() if isinstance(v, np.ndarray) else [float(c) for c in v]
    if len(out) != 3:
        raise ValueError(f"expected 3 numbers, got {len(out)}")
    return (float(out[0]), float(out[1]), float(out[2]))


def _vector3(v) -> np.ndarray:
    """A 3-vector (ndarray or sequence) as a writable float64 array (the array itself when it
    is one: the kernels' signatures take writable arrays)."""
    if type(v) is np.ndarray and v.dtype == _F64 and v.shape == (3,) and v.flags.writeable:
        return v
    return np.array(_floats3(v))


def _matrix3(m) -> np.ndarray:
    """A 3x3 matrix (ndarray or nested sequence) as a writable float64 array."""
    if type(m) is np.ndarray and m.dtype == _F64 and m.shape == (3, 3):
        return m if m.flags.writeable else m.copy()
    rows = m.tolist() if isinstance(m, np.ndarray) else list(m)
    if len(rows) != 3:
        raise ValueError("expected a 3x3 matrix")
    return np.array([_floats3(row) for row in rows])


def _quadratic_form(P: list, J: tuple) -> float:
    """J P J^T for a 6x6 matrix P (nested lists) and a row J of 6 floats, skipping J's zeros."""
    out = 0.0
    for j in range(6):
        c = J[j]
        if c:
            row = P[j]
            out += c * (
                row[0] * J[0]
                + row[1] * J[1]
                + row[2] * J[2]
                + row[3] * J[3]
                + row[4] * J[4]
                + row[5] * J[5]
            )
    return out


_NO_INPUT = np.empty(0)  # "not given" for _predict's velocity
_NO_MATRIX = np.empty((0, 0))  # "not given" for _predict's attitude


@dataclass(frozen=True)
class DkfConfig:
    meas_noise_px: float = 1.5  # detector noise on the centre, 1 sigma
    size_noise_px: float = 0.7  # detector noise on the apparent radius, 1 sigma
    size_noise_rel: float = 0.15  # relative error of the radius model (diameter, blob shape)
    target_diameter_m: float = 0.3  # the balloon the detector looks for
    init_range_m: float = 20.0  # depth prior when the first detection has no usable size
    init_target_speed_m_s: float = 3.0  # 1 sigma per ENU axis of the target's first velocity
    target_accel_noise_m_s2: float = 1.0  # random-walk density of v_t, m/s^2 per sqrt(Hz)
    flow_noise_px_s: float = 10.0  # white image-rate model error, px/s per sqrt(Hz)
    depth_noise_rel: float = 0.05  # white relative rate error of rho, 1/sqrt(s)
    min_depth_m: float = 0.1  # rho never exceeds 1 / min_depth_m
    gate_sigma: float = 5.0  # Mahalanobis gate on the point innovation (and on the size's)
    lost_timeout_s: float = 0.5  # no accepted detection for this long -> lost
    buffer_s: float = 0.6  # history kept; a detection older than this is rejected
    # a detection stamped up to this far after the filter's time (camera and IMU clocks a few
    # ms apart; with no camera delay the stamp can lead) is fused at the filter's time
    future_tolerance_s: float = 0.02

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"DkfConfig.{name} must be a positive number, got {value!r}")


class FusionResult(enum.Enum):
    INITIALISED = "initialised"
    ACCEPTED = "accepted"
    GATED = "gated"  # non-finite, or innovation beyond the Mahalanobis gate
    DUPLICATE = "duplicate"  # same capture time as one already fused
    TOO_OLD = "too_old"  # captured before the oldest buffered state
    FUTURE = "future"  # captured after the filter's current time


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class ImageEstimate:
    """The DKF's estimate at ``time_s`` (the time of its last prediction)."""

    time_s: float
    e_px: tuple[float, float]  # image error e = (u - c_u, v - c_v)
    e_rate_px_s: tuple[float, float]  # total rate: rotational + translational flow
    time_since_detection_s: float
    lost: bool


class _Meas:
    __slots__ = ("r_px", "t", "z")

    def __init__(self, t: float, z: np.ndarray, r_px: float | None) -> None:
        self.t = t
        self.z = z  # normalised image point (x_n, y_n)
        self.r_px = r_px  # apparent radius in px, or None when not usable


def _meas_time(m: _Meas) -> float:
    return m.t


class DelayedKalmanFilter:
    def __init__(self, camera: CameraModel, config: DkfConfig | None = None) -> None:
        self.camera = camera
        self._f = camera.f_px
        self.config = config or DkfConfig()
        # default inputs for callers that give only the gyro: vehicle still, body = world
        self._R_CB = np.ascontiguousarray(camera.R_BC.T.ravel(), dtype=np.float64)
        self._alloc(_CAPACITY)
        self._meas: list[_Meas] = []  # in capture order
        self._initialised = False
        self._last_accepted_s = -math.inf
        # a re-started track keeps the old one's depth and target velocity if it was last
        # confirmed less than this long ago (s; 0: every track starts afresh)
        self.carry_max_s = 0.0
        # the last dropped track's (time, v_t, P_vv): the velocity it knew when it was dropped
        self._memory: tuple[float, np.ndarray, np.ndarray] | None = None
        self.counts: dict[FusionResult, int] = {r: 0 for r in FusionResult}

    def _alloc(self, n: int) -> None:
        """The buffer's arrays for n rows (see the buffer layout above), empty."""
        self._T = np.zeros(n)
        self._U = np.zeros((n, 15))
        self._X = np.zeros((n, _N))
        self._F = np.zeros((n, 18))
        self._Q = np.zeros((n, _N))
        self._P = np.zeros((n, _N, _N))
        self._HX = np.zeros(n, dtype=np.uint8)
        self._HP = np.zeros(n, dtype=np.uint8)
        self._win = np.zeros(2, dtype=np.int64)  # the rows in use: [lo, hi)
        self._head_cache: tuple | None = None  # see _head

    @property
    def _lo(self) -> int:
        return int(self._win[0])

    @property
    def _hi(self) -> int:
        return int(self._win[1])

    def _make_room(self) -> None:
        """Free row hi: shift the window to the start of the arrays, or grow them."""
        lo, hi = self._lo, self._hi
        n = hi - lo
        cap = self._T.shape[0]
        arrays = ("_T", "_U", "_X", "_F", "_Q", "_P", "_HX", "_HP")
        if n + 1 > cap // 2:  # grow (to keep the shifts rare)
            old = {a: getattr(self, a) for a in arrays}
            self._alloc(2 * cap)
            for a in arrays:
                getattr(self, a)[:n] = old[a][lo:hi]
        else:
            for a in arrays:
                arr = getattr(self, a)
                arr[:n] = arr[lo:hi]
        self._win[:] = 0, n

    @property
    def config(self) -> DkfConfig:
        return self._config

    @config.setter
    def config(self, config: DkfConfig) -> None:
        self._config = config
        c, f = config, self._f
        self._r_point = (c.meas_noise_px / f) ** 2
        self._gate2_point = c.gate_sigma**2
        self._q_v = c.target_accel_noise_m_s2**2
        self._rho_max = 1.0 / c.min_depth_m
        self._radius_m = 0.5 * c.target_diameter_m
        prm = np.zeros(11)
        prm[_PRM_Q_IMG] = (c.flow_noise_px_s / f) ** 2
        prm[_PRM_Q_V] = self._q_v
        prm[_PRM_Q_RHO_REL] = c.depth_noise_rel**2
        prm[_PRM_RHO_MAX] = self._rho_max
        prm[_PRM_R_POINT] = self._r_point
        prm[_PRM_GATE2] = self._gate2_point
        prm[_PRM_RADIUS] = self._radius_m
        prm[_PRM_F] = f
        prm[_PRM_SIZE_VAR_PX] = c.size_noise_px**2
        prm[_PRM_SIZE_REL] = c.size_noise_rel
        prm[_PRM_TWO] = 2.0
        self._prm = prm

    # ----------------------------------------------------------------- propagation
    def _step(self, x, P: np.ndarray, i: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Propagate (x, P) by dt with buffer row i's inputs: returns (x', P')."""
        x1, F, Q = np.empty(_N), np.empty(18), np.empty(_N)
        _step_x(np.array(x, dtype=np.float64), self._U[i], dt, self._prm, x1, F, Q)
        return x1, _propagate(np.ascontiguousarray(P), F, Q)

    def _covariance(self, i: int) -> np.ndarray | None:
        """P at buffer row i (absolute), propagated from the last row before it that holds
        one (None without a track; the track is dropped if it turns non-finite)."""
        if self._HP[i]:
            return self._P[i]
        code = _covariance(self._P, self._F, self._Q, self._HX, self._HP, self._lo, i)
        if code == 1:
            return self._P[i]
        if code < 0:
            self._drop_track()
        return None

    def predict(
        self,
        time_s: float,
        gyro_rates_flu_rad_s: np.ndarray,
        velocity_enu_m_s: np.ndarray | None = None,
        R_WC: np.ndarray | None = None,
    ) -> None:
        """Advance to ``time_s`` with the body rate, vehicle velocity (ENU) and camera attitude
        (camera -> ENU) held since the previous call. Without velocity and attitude the vehicle
        is taken as still and level, and the target velocity state absorbs its motion. A time
        not after the last prediction, or not finite, changes nothing (a NaN row would stop the
        window from ever trimming; an infinite one would end every later prediction)."""
        lo, hi = self._win.tolist()
        if (hi > lo and time_s <= self._T.item(hi - 1) + _TIME_EPS_S) or not math.isfinite(time_s):
            return
        gyro = _vector3(gyro_rates_flu_rad_s)
        v_c = _NO_INPUT if velocity_enu_m_s is None else _vector3(velocity_enu_m_s)
        R = _NO_MATRIX if R_WC is None else _matrix3(R_WC)
        self._head_cache = None
        if self._initialised and hi > lo and not self._HX[hi - 1]:
            self._drop_track()  # no state to step on (the kernel would step a stale row's)
        if hi == self._T.shape[0]:
            self._make_room()
        T = self._T
        horizon = time_s - self._config.buffer_s
        code = _predict(
            T, self._U, self._X, self._F, self._Q, self._P, self._HX, self._HP, self._win,
            self._initialised, float(time_s), horizon, gyro, v_c, R, self._R_CB, self._prm,
        )  # fmt: skip
        if code < 0:  # the track is lost: drop it, then the rows older than the horizon
            self._drop_track()
            lo, hi = self._win.tolist()
            while hi - lo > 2 and T[lo + 1] <= horizon:
                lo += 1
            self._win[0] = lo
        # measurements before the oldest buffered state can never be replayed again (they
        # are in capture order: none to cut unless the first one is)
        meas = self._meas
        if meas and meas[0].t < T.item(self._win.item(0)):
            lo = self._lo
            del meas[: bisect.bisect_left(meas, T[lo], key=_meas_time)]

    # ----------------------------------------------------------------- fusion
    @property
    def time_s(self) -> float:
        h = self._head()
        return h[1][-1] if h else -math.inf

    def fuse(self, det: Detection) -> FusionResult:
        """Fuse one detection at its capture time; returns what happened to it."""
        result = self._fuse(det)
        self._head_cache = None
        self.counts[result] += 1
        return result

    def _measurement(self, det: Detection) -> _Meas | None:
        """The detection as a measurement, or None when it is not finite."""
        cam = self.camera
        try:
            cu, cv = det.center_px
            u, v, t_c = float(cu), float(cv), float(det.capture_time_s)
        except (TypeError, ValueError):
            return None
        ex, ey = cam.error_px(u, v)
        if not (math.isfinite(ex) and math.isfinite(ey) and math.isfinite(t_c)):
            return None
        xn, yn = ex / self._f, ey / self._f
        if not (abs(xn) < _MAX_ABS_N and abs(yn) < _MAX_ABS_N):
            return None
        r_px = None
        try:
            area = float(det.area_px)
            bx, by, bw, bh = det.bbox_px
            bx, by, bw, bh = float(bx), float(by), float(bw), float(bh)
        except (TypeError, ValueError):
            area = math.nan
            bx = by = bw = bh = math.nan
        whole = bx > 0.5 and by > 0.5 and bx + bw < cam.width_px - 0.5
        whole = whole and by + bh < cam.height_px - 0.5
        if math.isfinite(area) and area > 0.0 and whole:
            r_px = math.sqrt(area / math.pi)
        return _Meas(t_c, np.array((xn, yn)), r_px)

    def _fuse(self, det: Detection) -> FusionResult:
        self._head_cache = None  # the states may change
        t_c = det.capture_time_s
        if not isinstance(t_c, int | float) or not math.isfinite(t_c):
            return FusionResult.GATED
        (lo, hi), T = self._win.tolist(), self._T
        if hi == lo or t_c > T[hi - 1] + self.config.future_tolerance_s:
            return FusionResult.FUTURE
        now = float(T[hi - 1])
        if t_c > now:
            t_c = now
            det = dataclasses.replace(det, capture_time_s=t_c)
        if t_c < T[lo] - _TIME_EPS_S:
            return FusionResult.TOO_OLD
        m = self._measurement(det)
        if m is None:
            return FusionResult.GATED
        if self._duplicate(t_c):
            return FusionResult.DUPLICATE
        if not self._initialised or now - self._last_accepted_s > self.config.lost_timeout_s:
            return self._initialise(m)
        # replay from the last buffered state strictly before t_c: an entry at exactly t_c
        # must come out of the replay with this measurement applied
        j = self._index_at_or_before(t_c - 2.0 * _TIME_EPS_S)
        if T[j] > (t_c - 2.0 * _TIME_EPS_S) + _TIME_EPS_S or not self._HX[j]:
            return FusionResult.TOO_OLD  # (the bound bisect used: no row before t_c)
        if self._meas and self._meas[-1].t > t_c:
            # out of order: full replay in capture order from just before t_c
            bisect.insort(self._meas, m, key=_meas_time)
            P = self._covariance(j)
            accepted = P is not None and self._replay(j, self._X[j], P, float(T[j]), t_c)
            if not accepted and any(o is m for o in self._meas):
                self._meas.remove(m)  # kept only if fused, as in order: no later replay retries it
        else:
            code = _fuse_latest(
                T, self._U, self._X, self._F, self._Q, self._P, self._HX, self._HP,
                self._win, j, m.t, float(m.z[0]), float(m.z[1]),
                math.nan if m.r_px is None else m.r_px, self._prm,
            )  # fmt: skip
            accepted = code == 1
            if code < 0:
                self._drop_track()
            elif accepted:
                self._meas.append(m)
                self._last_accepted_s = max(self._last_accepted_s, m.t)
                if not _valid(self._X[hi - 1]):
                    self._drop_track()
        return FusionResult.ACCEPTED if accepted else FusionResult.GATED

    def _duplicate(self, t_c: float) -> bool:
        """Is a measurement within _TIME_EPS_S of ``t_c`` buffered? (Bisected: they are in
        capture order; the neighbours found are tested as a scan of all would test them.)"""
        meas = self._meas
        i = bisect.bisect_left(meas, t_c - 2.0 * _TIME_EPS_S, key=_meas_time)
        while i < len(meas) and meas[i].t <= t_c + 2.0 * _TIME_EPS_S:
            if abs(meas[i].t - t_c) < _TIME_EPS_S:
                return True
            i += 1
        return False

    def _index_at_or_before(self, t: float) -> int:
        """The buffer row (absolute) of the last prediction at or before t (the oldest if
        none is)."""
        lo, hi = self._win.tolist()
        return max(_bisect_right(self._T, lo, hi, t + _TIME_EPS_S) - 1, lo)

    def _drop_track(self) -> None:
        self._head_cache = None
        lo, hi = self._win.tolist()
        if self._initialised:
            # remember the target velocity at the last entry holding a covariance (v_t is a
            # random walk: from there on only its variance grows, by q_v per second)
            for i in range(hi - 1, lo - 1, -1):
                if self._HX[i] and self._HP[i]:
                    v, P_vv = self._X[i, 3:].copy(), self._P[i, 3:, 3:].copy()
                    if math.isfinite(float(v.sum() + P_vv.sum())):
                        self._memory = (float(self._T[i]), v, P_vv)
                    break
        self._HX[lo:hi] = 0
        self._HP[lo:hi] = 0
        self._meas = []
        self._initialised = False

    def _carried(self, m: _Meas) -> tuple[tuple, np.ndarray] | None:
        """The state and covariance to restart a track from at m (capture time m.t), keeping
        what the old track still knows (DESIGN.md §4; README "Track loss"), or None when it
        knows nothing useful. The image point is m's. The target velocity is the old track's,
        its covariance grown by the random walk over the time without measurements
        (P_vv + q_v dt I), if no component is vaguer than the first-detection prior. While the
        old track is still propagated and m falls inside its (grown) image gate, its depth
        and the depth-velocity covariance are kept too and m's apparent size is fused into
        them; otherwise the depth restarts from m's size (or the prior) as for a new track."""
        if m.t - self._last_accepted_s > self.carry_max_s:
            return None
        c = self.config
        s_v2 = c.init_target_speed_m_s**2
        j = self._index_at_or_before(m.t)
        x = P = None
        if self._initialised and self._HX[j]:
            P = self._covariance(j)
            x = self._X[j]
            if P is not None and m.t > self._T[j] + _TIME_EPS_S and j + 1 < self._hi:
                x, P = self._step(x, P, j + 1, m.t - float(self._T[j]))
            if P is None or not (_valid(x) and math.isfinite(float(P.trace()))):
                x = P = None
        if P is not None:
            if float(max(P[3, 3], P[4, 4], P[5, 5])) > s_v2:
                return None
            r = self._r_point
            y0, y1 = float(m.z[0] - x[0]), float(m.z[1] - x[1])
            s00, s01, s11 = float(P[0, 0]) + r, float(P[0, 1]), float(P[1, 1]) + r
            det = s00 * s11 - s01 * s01
            d2 = (s11 * y0 * y0 - 2.0 * s01 * y0 * y1 + s00 * y1 * y1) / det if det > 0 else 1e9
            if d2 <= self._gate2_point:
                # m where the old track predicted it: keep depth and velocity with their
                # covariance, reset the image point (variance 1, ~45 deg: uncorrelated) and
                # fuse m into it (the point, then its size against the carried depth)
                P0 = P.copy()
                P0[:2, :] = 0.0
                P0[:, :2] = 0.0
                P0[0, 0] = P0[1, 1] = 1.0
                x0, P0, ok = self._update(x.copy(), P0, m)
                return (x0, P0) if ok else None
            v, P_vv = x[3:].copy(), P[3:, 3:].copy()
        elif self._memory is not None:
            t0, v, P_vv = self._memory
            P_vv = P_vv + np.eye(3) * (self._q_v * max(m.t - t0, 0.0))
            if float(max(np.diag(P_vv))) > s_v2:
                return None
        else:
            return None
        x0, P0 = self._fresh(m)
        x0 = (*x0[:3], *v.tolist())
        P0[3:, 3:] = P_vv
        return x0, P0

    def _fresh(self, m: _Meas) -> tuple[tuple, np.ndarray]:
        """A new track's state and covariance at m: the image point, the depth from the
        apparent size (or the prior range), the target velocity 0 +- init_target_speed_m_s."""
        c = self.config
        xn, yn = float(m.z[0]), float(m.z[1])
        n2 = 1.0 + xn * xn + yn * yn
        if m.r_px is not None:
            # r = f R rho / sqrt(n2 - R^2 rho^2)  =>  rho = r sqrt(n2) / sqrt(f^2 R^2 + r^2 R^2)
            R = self._radius_m
            rho = m.r_px * math.sqrt(n2) / (R * math.hypot(self._f, m.r_px))
            rel = math.hypot(c.size_noise_rel, c.size_noise_px / m.r_px)
            s_rho = 2.0 * rel * rho
        else:
            rho = math.sqrt(n2) / c.init_range_m
            s_rho = rho
        rho = min(rho, self._rho_max)
        s_n = c.meas_noise_px / self._f
        s_v = c.init_target_speed_m_s
        x0 = (xn, yn, rho, 0.0, 0.0, 0.0)
        P0 = np.diag([s_n**2, s_n**2, s_rho**2, s_v**2, s_v**2, s_v**2])
        return x0, P0

    def _initialise(self, m: _Meas) -> FusionResult:
        carried = self._carried(m) if self.carry_max_s > 0.0 else None
        self._drop_track()
        self._meas = [m]
        x0, P0 = self._fresh(m) if carried is None else carried
        x0 = np.array(x0, dtype=np.float64)
        P0 = np.ascontiguousarray(P0, dtype=np.float64)
        j = self._index_at_or_before(m.t)
        # row j is at t_c by the same test that found it (T[j] <= t_c + eps): a stamp a rounding
        # error short of eps before the newest row must still write the new track's state there
        if m.t - _TIME_EPS_S <= self._T[j] <= m.t + _TIME_EPS_S:
            self._X[j], self._P[j] = x0, P0
            self._HX[j] = self._HP[j] = 1
        self._initialised = True
        self._last_accepted_s = m.t
        # the state at t_c is the measurement itself; replay forward from there
        self._replay(j, x0, P0, m.t, None)
        return FusionResult.INITIALISED

    def _replay(self, j: int, x, P, t: float, new_t_c: float | None) -> bool:
        """From state (x, P) at time t inside buffer interval j, re-run every later buffered
        step, fusing stored measurements after t in capture order. Writes states back."""
        meas = self._meas
        k = bisect.bisect_right(meas, t + _TIME_EPS_S, key=_meas_time)
        mt = np.array([o.t for o in meas], dtype=np.float64)
        mz = np.array([o.z for o in meas], dtype=np.float64).reshape(len(meas), 2)
        mr = np.array([math.nan if o.r_px is None else o.r_px for o in meas], dtype=np.float64)
        last = np.array([self._last_accepted_s])
        hi = self._hi
        new_accepted = _replay(
            self._T, self._U, self._X, self._F, self._Q, self._P, self._HX, self._HP, hi, j,
            np.array(x, dtype=np.float64), np.array(P, dtype=np.float64), float(t),
            mt, mz, mr, k, math.nan if new_t_c is None else float(new_t_c), self._prm, last,
        )  # fmt: skip
        self._last_accepted_s = float(last[0])
        if not (self._HX[hi - 1] and self._HP[hi - 1]):
            return new_accepted  # no later entry (j is the newest) and none at j
        if not (_valid(self._X[hi - 1]) and math.isfinite(float(self._P[hi - 1].trace()))):
            self._drop_track()
        return new_accepted

    def _update(self, x, P: np.ndarray, m: _Meas) -> tuple[tuple, np.ndarray, bool]:
        """Gated EKF update of (x, P) with m (the kernel :func:`_update`): returns x as 6
        floats, P and whether it was accepted (x and P unchanged when not)."""
        x_out, P_out = np.empty(_N), np.empty((_N, _N))
        x = np.array(x, dtype=np.float64)
        r_px = math.nan if m.r_px is None else float(m.r_px)
        ok = _update(
            x, np.ascontiguousarray(P, dtype=np.float64), float(m.z[0]), float(m.z[1]), r_px,
            self._prm, x_out, P_out,
        )  # fmt: skip
        if not ok:
            return tuple(x.tolist()), P, False
        return tuple(x_out.tolist()), P_out, True

    # ----------------------------------------------------------------- outputs
    def lost(self, now_s: float | None = None) -> bool:
        now = self.time_s if now_s is None else now_s
        return (not self._initialised) or (now - self._last_accepted_s > self.config.lost_timeout_s)

    def _head(self) -> tuple:
        """The newest rows as Python floats, read once per change of the buffer: (index of
        the newest row, times, state-held flags and states of the newest two rows, the
        newest row's inputs), or () when the buffer is empty."""
        h = self._head_cache
        if h is None:
            lo, hi = self._win.tolist()
            if hi == lo:
                h = ()
            else:
                k = max(hi - 2, lo)
                T, HX, X = self._T[k:hi].tolist(), self._HX[k:hi].tolist(), self._X[k:hi].tolist()
                h = (hi - 1, T, HX, X, self._U[hi - 1].tolist())
            self._head_cache = h
        return h

    def _tracked(self) -> tuple | None:
        """The newest row as (index, time, state, inputs) when it holds a state (a track)."""
        if not self._initialised:
            return None
        h = self._head()
        if not h or not h[2][-1]:
            return None
        return h[0], h[1][-1], h[3][-1], h[4]

    def _read(self, at_s: float | None = None) -> tuple:
        """:func:`_view`'s 14 floats (the estimate, the error at ``at_s``, the range)."""
        return _view(
            self._T, self._U, self._X, self._HX, self._win, self._initialised,
            self._last_accepted_s, self._config.lost_timeout_s, self._f,
            at_s is not None, math.nan if at_s is None else at_s,
        )  # fmt: skip

    def view(
        self, at_s: float | None = None
    ) -> tuple[ImageEstimate | None, tuple[float, float] | None, float | None]:
        """A control tick's reads in one kernel call: :meth:`estimate`, :meth:`e_px_at` of
        ``at_s`` (None without it) and :meth:`range_m`."""
        r = self._read(at_s)
        if r[0] == 0.0:
            est = rng = None
        else:
            est = ImageEstimate(r[1], (r[2], r[3]), (r[4], r[5]), r[6], r[7] != 0.0)
            rng = r[13]
        return est, ((r[11], r[12]) if r[10] != 0.0 else None), rng

    def estimate(self) -> ImageEstimate | None:
        """Current estimate (at the last prediction time), or None before the first detection."""
        return self.view()[0]

    def state_vector(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The current estimate as (e_x, e_y, r_x, r_y) in px and px/s, r being the image rate
        the camera's rotation does not explain, and the diagonal of its covariance (r's
        variance through the Jacobian of the translational flow)."""
        head = self._tracked()
        if head is None or self._covariance(head[0]) is None:
            return None
        i, _, x, u = head
        f = self._f
        tr = self._read()[8:10]  # the translational flow (px/s)
        # in floats (numpy's per-call cost on these small arrays is most of the work): J is
        # the Jacobian of the translational flow rho (u_xy - s_xy u_z), u = R_CW (v_t - v_c)
        xn, yn, rho, vE, vN, vU = x
        _, _, _, c0, c1, c2, r0, r1, r2, r3, r4, r5, r6, r7, r8 = u
        dE, dN, dU = vE - c0, vN - c1, vU - c2
        u0 = r0 * dE + r1 * dN + r2 * dU
        u1 = r3 * dE + r4 * dN + r5 * dU
        u2 = r6 * dE + r7 * dN + r8 * dU
        a = rho * u2
        jx = (
            -a,
            0.0,
            u0 - xn * u2,
            rho * (r0 - xn * r6),
            rho * (r1 - xn * r7),
            rho * (r2 - xn * r8),
        )
        jy = (
            0.0,
            -a,
            u1 - yn * u2,
            rho * (r3 - yn * r6),
            rho * (r4 - yn * r7),
            rho * (r5 - yn * r8),
        )
        P = self._P[i].tolist()
        var_r = (_quadratic_form(P, jx), _quadratic_form(P, jy))
        state = np.array([xn * f, yn * f, tr[0], tr[1]])
        cov = np.array([P[0][0] * f * f, P[1][1] * f * f, var_r[0] * f * f, var_r[1] * f * f])
        return state, cov

    def range_m(self) -> float | None:
        """Current range along the line of sight (m) from the mean alone (no covariance), or
        None without a track."""
        return self.view()[2]

    def image_std_px(self) -> tuple[float, float] | None:
        """The 1-sigma of the current image point (px, x and y), or None without a track
        (propagates the covariance if it is still lazy)."""
        head = self._tracked()
        if head is None:
            return None
        P = self._covariance(head[0])
        if P is None:
            return None
        f = self._f
        return math.sqrt(max(float(P[0, 0]), 0.0)) * f, math.sqrt(max(float(P[1, 1]), 0.0)) * f

    def depth_velocity(self) -> tuple[float, np.ndarray, np.ndarray] | None:
        """Current range along the line of sight (m), the target's velocity (ENU, m/s) and the
        full 6x6 covariance of the internal state, or None without a track."""
        head = self._tracked()
        if head is None:
            return None
        P = self._covariance(head[0])
        if P is None:
            return None
        xn, yn, rho = head[2][:3]
        return math.sqrt(1.0 + xn * xn + yn * yn) / rho, np.array(head[2][3:]), P.copy()

    def e_px_at(self, time_s: float) -> tuple[float, float] | None:
        """The buffered (replay-corrected) image error at a past prediction time, if held."""
        return self.view(time_s)[1]
