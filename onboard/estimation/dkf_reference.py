"""The delayed Kalman filter's kernels (:mod:`.dkf_kernels`) written as the filter is stated in
DESIGN.md §4: 6x6 matrices, the transition F and measurement Jacobian H formed explicitly, the
Joseph-form update, named constants (:class:`~.dkf_values.DkfConfig` and the focal length f).
The specification the compiled kernels are checked against (tests/test_kernel_references.py).

State x = (x_n, y_n, rho, v_t) (image point / f, inverse depth 1/m, target velocity ENU m/s).
The buffer is the kernels' own: a window [lo, hi) of rows (time T, inputs U = (omega_c, v_c,
R_CW row-major), state X, the first three rows of F, Q's diagonal, covariance P, whether X and
P are held: HX, HP)."""

from __future__ import annotations

import math

import numpy as np

from .dkf_kernels import _MAX_ABS_N, _MIN_SZ, _TIME_EPS_S
from .dkf_values import DkfConfig


def inputs(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A buffer row's inputs: (omega_c camera-frame rate, v_c ENU velocity, R_CW)."""
    return u[0:3], u[3:6], u[6:15].reshape(3, 3)


def transition(f_rows: np.ndarray) -> np.ndarray:
    """The 6x6 F from its stored first three rows (v_t is a random walk: identity below)."""
    F = np.eye(6)
    F[:3] = f_rows.reshape(3, 6)
    return F


def valid(x: np.ndarray) -> bool:
    """In view (|x_n|, |y_n| < 4, ~76 deg), in front (rho > 0) and a finite velocity."""
    return bool(
        abs(x[0]) < _MAX_ABS_N and abs(x[1]) < _MAX_ABS_N and x[2] > 0 and np.isfinite(x[3:]).all()
    )


def process_step(
    x: np.ndarray, u: np.ndarray, dt: float, c: DkfConfig, f_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One step of the process model over dt with the inputs u held:

    s = (x_n, y_n, 1), u_rel = R_CW (v_t - v_c), s' = s + dt (rho u_rel - omega_c x s)
    (s'_z at least 0.2), x' = (s'_x / s'_z, s'_y / s'_z, min(rho / s'_z, rho_max), v_t);
    F its Jacobian (chain rule of the quotient through s'), Q = diag(q_img, q_img,
    q_rho rho'^2, q_v, q_v, q_v) dt. Returns (x', F, Q) with F and Q 6x6."""
    omega, v_c, R_CW = inputs(u)
    rho, v_t = x[2], x[3:]
    s = np.array([x[0], x[1], 1.0])
    u_rel = R_CW @ (v_t - v_c)
    s1 = s + dt * (rho * u_rel - np.cross(omega, s))
    s_z = max(s1[2], _MIN_SZ)
    rho1 = min(rho / s_z, 1.0 / c.min_depth_m)
    x1 = np.array([s1[0] / s_z, s1[1] / s_z, rho1, *v_t])
    # ds'/dx: d/dx_n and d/dy_n of s - dt omega x s, dt u_rel for rho, dt rho R_CW for v_t
    J = np.zeros((3, 6))
    for i in range(2):
        e = np.eye(3)[i]
        J[:, i] = e - dt * np.cross(omega, e)
    J[:, 2] = dt * u_rel
    J[:, 3:] = dt * rho * R_CW
    F = np.eye(6)
    F[0] = (J[0] - x1[0] * J[2]) / s_z
    F[1] = (J[1] - x1[1] * J[2]) / s_z
    F[2] = (np.eye(6)[2] - rho1 * J[2]) / s_z
    q_img = (c.flow_noise_px_s / f_px) ** 2
    q_v = c.target_accel_noise_m_s2**2
    Q = np.diag([q_img, q_img, c.depth_noise_rel**2 * rho1**2, q_v, q_v, q_v]) * dt
    return x1, F, Q


def propagate(P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """P' = F P F^T + Q."""
    return F @ P @ F.T + Q


def update(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, r_px: float, c: DkfConfig, f_px: float
) -> tuple[bool, np.ndarray, np.ndarray]:
    """The gated EKF update with the image point z (H = [I_2 0], R = (sigma_px / f)^2 I,
    Mahalanobis gate on y^T S^-1 y), then, relinearised at the updated state, the apparent
    radius r_px (NaN: not usable) with h(x) = f R rho / sqrt(n2), n2 = 1 + x_n^2 + y_n^2 -
    R^2 rho^2, variance sigma_s^2 + (rel h)^2 at the predicted radius h (a variance from the
    measured radius would weight the blobs measured too small more, biasing rho low), within
    its own gate. Joseph form
    P = (I - K H) P (I - K H)^T + K R K^T; rho kept in [1e-6, rho_max]; P symmetrised.
    Returns (accepted, x, P); (False, x, P) unchanged when the point is gated."""
    gate2 = c.gate_sigma**2
    r = (c.meas_noise_px / f_px) ** 2
    H = np.zeros((2, 6))
    H[0, 0] = H[1, 1] = 1.0
    y = z - H @ x
    S = H @ P @ H.T + r * np.eye(2)
    if not np.linalg.det(S) > 0.0:
        return False, x, P
    if not y @ np.linalg.solve(S, y) <= gate2:
        return False, x, P
    K = P @ H.T @ np.linalg.inv(S)
    x = x + K @ y
    I_KH = np.eye(6) - K @ H
    P = I_KH @ P @ I_KH.T + r * K @ K.T
    if not math.isnan(r_px):
        R_m = 0.5 * c.target_diameter_m
        x_n, y_n, rho = x[0], x[1], x[2]
        n2 = max(1.0 + x_n**2 + y_n**2 - (R_m * rho) ** 2, 1e-6)
        d = f_px * R_m / n2**1.5
        h = np.zeros(6)
        h[:3] = -d * rho * x_n, -d * rho * y_n, d * (n2 + (R_m * rho) ** 2)
        h_s = f_px * R_m * rho / math.sqrt(n2)
        var_s = c.size_noise_px**2 + (c.size_noise_rel * h_s) ** 2
        y_s = r_px - h_s
        s_s = h @ P @ h + var_s
        if y_s**2 <= gate2 * s_s:
            k = P @ h / s_s
            x = x + k * y_s
            I_kh = np.eye(6) - np.outer(k, h)
            P = I_kh @ P @ I_kh.T + var_s * np.outer(k, k)
    x = x.copy()
    x[2] = min(max(x[2], 1e-6), 1.0 / c.min_depth_m)
    return True, x, 0.5 * (P + P.T)


def covariance(buf: dict, lo: int, i: int) -> int:
    """P at row i, propagated row by row (P_n = F_n P_{n-1} F_n^T + Q_n) from the last row
    before it that holds one. 1: held; 0: no state at i; -1: nothing to start from; -2: not
    finite (the track is to be dropped)."""
    P, HP, HX = buf["P"], buf["HP"], buf["HX"]
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
        P[n] = propagate(P[n - 1], transition(buf["F"][n]), np.diag(buf["Q"][n]))
        HP[n] = 1
    return 1 if np.isfinite(np.trace(P[i])) else -2


def _store_step(buf: dict, n: int, x1: np.ndarray, F: np.ndarray, Q: np.ndarray) -> None:
    buf["X"][n], buf["F"][n], buf["Q"][n] = x1, F[:3].ravel(), np.diag(Q)


def fuse_latest(
    buf: dict, j: int, t_c: float, z: np.ndarray, r_px: float, c: DkfConfig, f_px: float
) -> int:
    """Fuse a measurement captured at t_c in (T_j, T_j+1], later than every stored one: the
    state and covariance of row j propagated to t_c, updated, propagated to row j + 1 with the
    rest of the step (F of the whole step stays buffered); the correction dx carried to the
    newest row through the buffered transitions, dx_k = F_k dx_{k-1} (the linearised replay;
    rho kept in [1e-6, rho_max], those rows' P to be propagated again). 1: accepted; 0: gated;
    < 0: :func:`covariance` failed."""
    code = covariance(buf, buf["win"][0], j)
    if code < 1:
        return code
    T, U, X = buf["T"], buf["U"], buf["X"]
    x, F, Q = process_step(X[j], U[j + 1], t_c - T[j], c, f_px)
    ok, x_u, P_u = update(x, propagate(buf["P"][j], F, Q), z, r_px, c, f_px)
    if not ok:
        return 0
    x1, F, Q = process_step(x_u, U[j + 1], T[j + 1] - t_c, c, f_px)
    buf["P"][j + 1] = propagate(P_u, F, Q)
    buf["HP"][j + 1] = 1
    dx = x1 - X[j + 1]
    X[j + 1] = x1
    for k in range(j + 2, buf["win"][1]):
        dx = transition(buf["F"][k]) @ dx
        X[k] = X[k] + dx
        X[k, 2] = min(max(X[k, 2], 1e-6), 1.0 / c.min_depth_m)
        buf["HP"][k] = 0
    return 1


def replay(
    buf: dict,
    hi: int,
    j: int,
    x: np.ndarray,
    P: np.ndarray,
    t: float,
    meas: list[tuple[float, np.ndarray, float]],
    k: int,
    new_t_c: float,
    last: np.ndarray,
    c: DkfConfig,
    f_px: float,
) -> bool:
    """From (x, P) at time t inside interval j, re-run every later buffered step with its
    inputs, fusing the stored measurements (t_c, z, r_px) from index k on in capture order, and
    write every state and covariance back. last[0] rises to each accepted capture time.
    Returns whether the one captured at ``new_t_c`` was accepted."""
    new_accepted = False
    T, U = buf["T"], buf["U"]
    for i in range(j + 1, hi):
        while k < len(meas) and meas[k][0] <= T[i] + _TIME_EPS_S:
            t_k, z, r_px = meas[k]
            x, F, Q = process_step(x, U[i], t_k - t, c, f_px)
            P = propagate(P, F, Q)
            t = t_k
            ok, x_u, P_u = update(x, P, z, r_px, c, f_px)
            if ok:
                x, P = x_u, P_u
                last[0] = max(last[0], t_k)
            if t_k == new_t_c:
                new_accepted = ok
            k += 1
        x, F, Q = process_step(x, U[i], T[i] - t, c, f_px)
        _store_step(buf, i, x, F, Q)
        P = propagate(P, F, Q)
        t = T[i]
        buf["P"][i] = P
        buf["HX"][i] = buf["HP"][i] = 1
    return new_accepted


def predict(
    buf: dict,
    tracking: bool,
    time_s: float,
    horizon_s: float,
    omega_b: np.ndarray,
    v_c: np.ndarray | None,
    R_WC: np.ndarray | None,
    R_CB: np.ndarray,
    c: DkfConfig,
    f_px: float,
) -> int:
    """Append the prediction at ``time_s``: its inputs (omega_c = R_CB omega_b; v_c, or 0;
    R_CW = R_WC^T, or R_CB: level), each non-finite one replaced by the previous row's (or the
    default), and, when tracking, the state stepped from the newest row (-1 if it leaves the
    view). Then the rows at or before ``horizon_s`` leave the window (the newest two stay),
    the oldest remaining one's covariance propagated first (-2 if not finite). 1: stepped;
    0: not tracking."""
    T, U, win = buf["T"], buf["U"], buf["win"]
    lo, hi = int(win[0]), int(win[1])
    given = [
        R_CB @ omega_b,
        np.zeros(3) if v_c is None else v_c,
        (R_CB if R_WC is None else R_WC.T).ravel(),
    ]
    defaults = [np.zeros(3), np.zeros(3), R_CB.ravel()]
    for (a, b), value, default in zip(((0, 3), (3, 6), (6, 15)), given, defaults, strict=True):
        if not math.isfinite(float(np.sum(value))):
            value = U[hi - 1, a:b] if hi > lo else default
        U[hi, a:b] = value
    T[hi] = time_s
    buf["HX"][hi] = buf["HP"][hi] = 0
    win[1] = hi + 1
    code = 0
    if tracking:
        x1, F, Q = process_step(buf["X"][hi - 1], U[hi], time_s - T[hi - 1], c, f_px)
        _store_step(buf, hi, x1, F, Q)
        if not valid(x1):
            return -1
        buf["HX"][hi] = 1
        code = 1
    hi += 1
    while hi - lo > 2 and T[lo + 1] <= horizon_s:
        if not buf["HP"][lo + 1] and buf["HX"][lo + 1] and covariance(buf, lo, lo + 1) < 0:
            return -2
        lo += 1
        win[0] = lo
    return code


def view(
    buf: dict,
    tracking: bool,
    last_accepted_s: float,
    lost_timeout_s: float,
    f_px: float,
    at_s: float | None,
) -> tuple:
    """A tick's reads: at the newest row (when tracking and it holds a state) e = f (x_n, y_n)
    and its rate f (L_s's rotational columns omega_c + rho (u_xy - s_xy u_z)) (eq. 4), the
    time since the last accepted detection, whether that is beyond the timeout, the
    translational flow and the range sqrt(1 + x_n^2 + y_n^2) / rho; the buffered error at
    ``at_s`` if a row there holds a state. The kernel's 14 floats, nan where absent."""
    T, X, U, HX = buf["T"], buf["X"], buf["U"], buf["HX"]
    lo, hi = int(buf["win"][0]), int(buf["win"][1])
    nan = math.nan
    out = [0.0, *[nan] * 9]
    rng = nan
    if tracking and hi > lo and HX[hi - 1]:
        i = hi - 1
        x_n, y_n, rho = X[i, :3]
        omega, v_c, R_CW = inputs(U[i])
        u_rel = R_CW @ (X[i, 3:] - v_c)
        L_rot = np.array([[x_n * y_n, -(1 + x_n**2), y_n], [1 + y_n**2, -x_n * y_n, -x_n]])
        trans = rho * (u_rel[:2] - np.array([x_n, y_n]) * u_rel[2])
        rate = (L_rot @ omega + trans) * f_px
        since = T[i] - last_accepted_s
        out = [1.0, T[i], x_n * f_px, y_n * f_px, *rate, since, float(since > lost_timeout_s)]
        out += list(trans * f_px)
        rng = math.sqrt(1 + x_n**2 + y_n**2) / rho if rho > 0 else math.inf
    at = [0.0, nan, nan]
    if at_s is not None:
        for k in range(hi - 1, lo - 1, -1):
            if abs(T[k] - at_s) < _TIME_EPS_S:
                if HX[k]:
                    at = [1.0, X[k, 0] * f_px, X[k, 1] * f_px]
                break
            if T[k] < at_s:
                break
    return (*out, *at, rng)
