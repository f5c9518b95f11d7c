"""Each compiled kernel and its reference (the readable statement in the paper's notation):
how to call both on one set of the kernel's arguments and which numbers must agree.

:data:`CASES` maps a kernel's qualified name to a function ``check(args) -> pairs`` that runs
the kernel on copies of ``args`` and its reference on the same values, and returns the pairs
(kernel's numbers, reference's numbers) to compare, or None when the arguments are outside
the reference's domain (gains outside their declared ranges after a perturbation).
:data:`COVERED` names the helper kernels that have no reference of their own, with the
reference that covers them. :data:`FRESH` draws arguments for kernels a recorded sortie may
not reach (other target motions). The simulator's kernels are registered by
:mod:`tests.kernel_cases_sim`."""

from __future__ import annotations

import bisect
import copy
import math
from collections.abc import Callable

import numpy as np

from onboard import camera_model, geometry
from onboard import geometry_reference as GR  # noqa: N812
from onboard.control import attitude, disturbance, los, png
from onboard.control import attitude_reference as AR  # noqa: N812
from onboard.control import guidance_reference as R  # noqa: N812
from onboard.estimation import dkf_kernels as K  # noqa: N812
from onboard.estimation import dkf_reference as DR  # noqa: N812
from onboard.estimation.dkf_values import DkfConfig
from onboard.gains import GAIN_NAMES, GainError, Gains

Pairs = list[tuple[object, object]] | None

CASES: dict[str, Callable[[tuple], Pairs]] = {}
FRESH: dict[str, Callable[[np.random.Generator], tuple]] = {}

# helpers with no reference of their own: each is one line a reader checks by eye, and the
# reference of every kernel that calls it checks it along with its caller
COVERED = {
    "onboard.control.los._min": "Python's min(a, b); covered by png_floats, fov_guard_floats",
    "onboard.control.los._max": "Python's max(a, b); covered by png_floats, fov_guard_floats",
    "onboard.control.los._exact_square": "Dekker's exact square; covered by hypot2 (math.hypot)",
    "groundstation.sim.random_processes.gauss_markov_factors": "a = exp(-dt/tau), "
    "b = sigma sqrt(1-a^2); covered by advance_errors",
    "groundstation.sim.random_processes.gauss_markov_step": "x <- a x + b n; "
    "covered by advance_errors",
    "groundstation.sim.random_processes.random_walk_step": "x <- x + s n; "
    "covered by advance_errors",
}


def case(kernel: Callable) -> Callable:
    """Register ``check`` as the case of ``kernel``."""

    def register(check: Callable[[tuple], Pairs]) -> Callable[[tuple], Pairs]:
        fn = getattr(kernel, "py_func", kernel)
        CASES[f"{fn.__module__}.{fn.__name__}"] = check
        check.kernel = kernel
        return check

    return register


def _copy(args: tuple) -> tuple:
    return copy.deepcopy(args)


def _gains(**values: float) -> Gains | None:
    try:
        return Gains().replace(**values)
    except GainError:
        return None


def _v(*xs: float) -> np.ndarray:
    return np.array(xs, dtype=float)


# ---------------------------------------------------------------- geometry and camera
@case(geometry.wrap_pi)
def _(a):
    return [(geometry.wrap_pi(*a), GR.wrap_pi(a[0]))]


@case(geometry.rotmat_of_quat)
def _(a):
    return [(geometry.rotmat_of_quat(*_copy(a)), GR.rotation_of_quaternion(a[0]))]


@case(geometry.mat3_mul)
def _(a):
    return [(geometry.mat3_mul(*_copy(a)), a[0] @ a[1])]


@case(geometry.camera_attitude)
def _(a):
    return [(geometry.camera_attitude(*_copy(a)), GR.camera_attitude(a[0], a[1]))]


@case(geometry.body_and_camera_attitude)
def _(a):
    R_WB, R_WC = geometry.body_and_camera_attitude(*_copy(a))
    return [(R_WB, GR.rotation_of_quaternion(a[0])), (R_WC, GR.camera_attitude(a[0], a[1]))]


@case(geometry.quat_mul4)
def _(a):
    return [(geometry.quat_mul4(*a), GR.quaternion_product(_v(*a[:4]), _v(*a[4:])))]


@case(geometry.quat_exp3)
def _(a):
    return [(geometry.quat_exp3(*a), GR.quaternion_exp(_v(*a)))]


@case(geometry.propagated_quat)
def _(a):
    return [(geometry.propagated_quat(*a), GR.propagated_attitude(_v(*a[:4]), _v(*a[4:7]), a[7]))]


@case(geometry.carried_attitude)
def _(a):
    now, q, q_t, w, max_dt, max_rate = a[0], _v(*a[1:5]), a[5], _v(*a[6:9]), a[9], a[10]
    q1, t1 = GR.carried_attitude(now, q, q_t, w, max_dt, max_rate)
    return [(geometry.carried_attitude(*a), (*q1, t1))]


@case(geometry.attitude_jump_rad)
def _(a):
    R0, R1, w0, w1, w2, dt = a
    return [(geometry.attitude_jump_rad(*_copy(a)), GR.attitude_jump(R0, R1, _v(w0, w1, w2), dt))]


@case(camera_model.pixel_of)
def _(a):
    x, y, z, f, cu, cv = a
    want = GR.pixel_of(_v(x, y, z), f, _v(cu, cv))
    return [
        (camera_model.pixel_of(*a), (0.0, math.nan, math.nan) if want is None else (1.0, *want))
    ]


# ---------------------------------------------------------------- guidance
@case(los.los_floats)
def _(a):
    return [(los.los_floats(*_copy(a)), R.line_of_sight(_v(a[0], a[1]), a[2]))]


@case(los.hypot2)
def _(a):
    return [(los.hypot2(*a), math.hypot(*a))]


@case(los.angles_floats)
def _(a):
    return [(los.angles_floats(*a), R.direction_angles(_v(*a)))]


@case(los.normal_floats)
def _(a):
    return [(los.normal_floats(*a), R.normal_part(_v(*a[:3]), _v(*a[3:])))]


@case(los.saturate3)
def _(a):
    return [(los.saturate3(*a), R.saturate(_v(*a[:3]), a[3]))]


@case(los.smooth_los_change)
def _(a):
    return [(los.smooth_los_change(*a), R.smoothed_los_change(*a))]


@case(los.los_change)
def _(a):
    return [(los.los_change(*a), R.los_change((a[0], a[1]), (a[2], a[3])))]


@case(los.los_terms)
def _(a):
    ex, ey, f, R_WC, has_prev, exp, eyp, R_prev, dt, hold, hold_given, tau = a[:12]
    filt, flown, max_late = (a[12], a[13]), (a[14], a[15], a[16]), a[17]
    n_t, q_y, q_z, dq_y, dq_z, filt1, flown1 = R.los_terms(
        _v(ex, ey), f, R_WC, _v(exp, eyp) if has_prev else None, R_prev, dt,
        hold if hold_given else None, tau, filt, flown, max_late,
    )  # fmt: skip
    return [(los.los_terms(*_copy(a)), (*n_t, q_y, q_z, dq_y, dq_z, *filt1, *flown1))]


@case(png.ramped_speed_floats)
def _(a):
    speed, k_brake, v_max, k_a, dt = a
    g = _gains(k_brake=k_brake, v_max=v_max, k_a=k_a)
    return None if g is None else [(png.ramped_speed_floats(*a), R.ramped_speed(speed, dt, g))]


@case(png.min_pitch_rad)
def _(a):
    return [(png.min_pitch_rad(*a), R.min_pitch(*a))]


@case(png.fov_guard_floats)
def _(a):
    a0, a1, a2, top, hx, hy, q_y, margin, a_max = a
    g = _gains(fov_margin=math.degrees(margin), a_max=a_max)
    if g is None:
        return None
    acted, a_d = R.fov_guard(_v(a0, a1, a2), _v(hx, hy, 0.0), top, q_y, g)
    return [(png.fov_guard_floats(*a), (float(acted), *a_d))]


@case(png.edge_margin_floats)
def _(a):
    top, bottom, ax0, ax1, ax2, q_y = a
    return [(png.edge_margin_floats(*a), R.edge_margin((top, bottom), _v(ax0, ax1, ax2), q_y))]


@case(png.pursuit_floats)
def _(a):
    zone, k_pur, top, bottom, ax0, ax1, ax2, q_y = a
    g = _gains(pur_zone=math.degrees(zone), k_pur=k_pur)
    if g is None:
        return None
    want = R.pursuit_weight((top, bottom), _v(ax0, ax1, ax2), q_y, g)
    return [(png.pursuit_floats(*a), want)]


@case(png.midcourse_floats)
def _(a):
    g = _gains(tau_zem=a[1], r_mid=a[2])
    return None if g is None else [(png.midcourse_floats(*a), R.midcourse_weight(a[0], g))]


@case(png.zem_floats)
def _(a):
    v0, v1, v2, has_vt, t0, t1, t2, var, n0, n1, n2, tau = a
    g = _gains(tau_zem=tau)
    if g is None or tau <= 0.0:
        return None
    v_t = _v(t0, t1, t2) if has_vt else None
    want = R.zem_nulling_accel(_v(v0, v1, v2), v_t, var, _v(n0, n1, n2), g)
    return [(png.zem_floats(*a), want)]


@case(png.png_floats)
def _(a):
    dt, l0, l1, l2, q_y, dq_y, dq_z, v0, v1, v2, ax0, ax1, ax2, top, bottom, rng = a[:16]
    has_vt, t0, t1, t2, var_v, e0, e1, e2, G = a[16:]
    try:
        g = Gains(**dict(zip(GAIN_NAMES, G.tolist(), strict=True)))
    except GainError:
        return None
    a_d, s_y, s_z, hovering = R.png(
        dt, _v(l0, l1, l2), q_y, (dq_y, dq_z), _v(v0, v1, v2), _v(ax0, ax1, ax2),
        (top, bottom), rng, _v(t0, t1, t2) if has_vt else None, var_v, g, _v(e0, e1, e2),
    )  # fmt: skip
    return [(png.png_floats(*_copy(a)), (*a_d, s_y, s_z, float(hovering)))]


@case(png.believed_drag_floats)
def _(a):
    want = R.believed_drag(_v(*a[0:3]), _v(*a[3:6]), _v(*a[6:9]), a[9])
    return [(png.believed_drag_floats(*a), want)]


@case(png.drag_feedforward_floats)
def _(a):
    return [(png.drag_feedforward_floats(*a), max(-float(_v(*a[0:3]) @ _v(*a[3:6])), 0.0))]


# ---------------------------------------------------------------- attitude and observer
@case(attitude.attitude_floats)
def _(a):
    a0, a1, a2, R_WB, r_d, k_R, w_max, mass, t_max = a
    g = _gains(k_R=k_R, omega_max=w_max)
    if g is None:
        return None
    w, thrust = AR.attitude(_v(a0, a1, a2), R_WB, r_d, g, mass, t_max)
    return [(attitude.attitude_floats(*_copy(a)), (*w, thrust))]


@case(attitude.command_floats)
def _(a):
    a0, a1, a2, ff, d0, d1, d2, v0, v1, v2, v_min, R_WB, r_d, k_R, w_max = a[:15]
    mass, t_max, hover = a[15:]
    g = _gains(v_min=v_min, k_R=k_R, omega_max=w_max)
    if g is None:
        return None
    w, thrust, guard, a_n = AR.command(
        _v(a0, a1, a2), _v(d0, d1, d2) if ff else None, _v(v0, v1, v2), R_WB, r_d, g,
        mass, t_max, hover,
    )  # fmt: skip
    return [(attitude.command_floats(*_copy(a)), (*w, thrust, float(guard), a_n))]


@case(disturbance.feedforward_floats)
def _(a):
    want = AR.feedforward(_v(*a[:3]), _v(*a[3:6]), a[6])
    return [(disturbance.feedforward_floats(*a), want)]


@case(disturbance.observer_step)
def _(a):
    dt, thrust, cmd, tau, mass, kd = a[:6]
    zp, z, h, e, v = (_v(*a[i : i + 3]) for i in (6, 9, 12, 15, 18))
    max_innov, bw, start, elapsed, max_d = a[21:26]
    t1, el1, h1, e1 = AR.observer_step(
        dt, thrust, cmd, tau, mass, kd, zp, z, h, e, v, max_innov, bw, start, elapsed, max_d
    )
    return [(disturbance.observer_step(*a[:26], 2.0), (t1, el1, *h1, *e1))]


# ---------------------------------------------------------------- the DKF
def _two(prm: np.ndarray) -> np.ndarray:
    """The constants with their exponent 2.0 (a perturbation must not change it)."""
    prm = prm.copy()
    prm[K._PRM_TWO] = 2.0
    return prm


def _config(prm: np.ndarray) -> tuple[DkfConfig, float]:
    """The DkfConfig and focal length the kernels' constants were made of."""
    f = prm[K._PRM_F]
    c = DkfConfig(  # the inverse of DelayedKalmanFilter.config's setter
        meas_noise_px=math.sqrt(prm[K._PRM_R_POINT]) * f,
        size_noise_px=math.sqrt(prm[K._PRM_SIZE_VAR_PX]),
        size_noise_rel=prm[K._PRM_SIZE_REL],
        target_diameter_m=2.0 * prm[K._PRM_RADIUS],
        target_accel_noise_m_s2=math.sqrt(prm[K._PRM_Q_V]),
        flow_noise_px_s=math.sqrt(prm[K._PRM_Q_IMG]) * f,
        depth_noise_rel=math.sqrt(prm[K._PRM_Q_RHO_REL]),
        min_depth_m=1.0 / prm[K._PRM_RHO_MAX],
        gate_sigma=math.sqrt(prm[K._PRM_GATE2]),
    )
    return c, f


_BUF = ("T", "U", "X", "F", "Q", "P", "HX", "HP")


def _buf(args: tuple, win: np.ndarray | None = None) -> dict:
    buf = dict(zip(_BUF, _copy(args), strict=True))
    if win is not None:
        buf["win"] = win.copy()
    return buf


def _compare_buffers(got: dict, want: dict, lo: int, hi: int) -> list[tuple[object, object]]:
    pairs: list[tuple[object, object]] = [
        (got["HX"][lo:hi], want["HX"][lo:hi]),
        (got["HP"][lo:hi], want["HP"][lo:hi]),
        (got["T"][lo:hi], want["T"][lo:hi]),
        (got["U"][lo:hi], want["U"][lo:hi]),
    ]
    for i in range(lo, hi):
        if got["HX"][i]:
            pairs += [(got["X"][i], want["X"][i]), (got["F"][i], want["F"][i])]
            pairs += [(got["Q"][i], want["Q"][i])]
        if got["HP"][i]:
            pairs.append((got["P"][i], want["P"][i]))
    return pairs


@case(K._valid)
def _(a):
    return [(K._valid(*_copy(a)), DR.valid(a[0]))]


@case(K._step_x)
def _(a):
    x, u, dt, prm = a[:4]
    prm = _two(prm)
    c, f = _config(prm)
    x1, F1, Q1 = np.empty(6), np.empty(18), np.empty(6)
    K._step_x(*_copy((x, u, dt, prm)), x1, F1, Q1)
    xr, Fr, Qr = DR.process_step(x, u, dt, c, f)
    return [(x1, xr), (F1, Fr[:3].ravel()), (Q1, np.diag(Qr))]


@case(K._propagate)
def _(a):
    P0, F, Q = a
    return [(K._propagate(*_copy(a)), DR.propagate(P0, DR.transition(F), np.diag(Q)))]


@case(K._update)
def _(a):
    x, P0, z0, z1, r_px, prm = a[:6]
    prm = _two(prm)
    c, f = _config(prm)
    x_out, P_out = np.empty(6), np.empty((6, 6))
    ok = K._update(*_copy((x, P0, z0, z1, r_px, prm)), x_out, P_out)
    ok_r, xr, Pr = DR.update(x, P0, _v(z0, z1), r_px, c, f)
    return [(ok, ok_r)] + ([(x_out, xr), (P_out, Pr)] if ok else [])


@case(K._covariance)
def _(a):
    got = {"P": a[0].copy(), "F": a[1], "Q": a[2], "HX": a[3].copy(), "HP": a[4].copy()}
    want = {"P": a[0].copy(), "F": a[1], "Q": a[2], "HX": a[3].copy(), "HP": a[4].copy()}
    lo, i = a[5], a[6]
    code = K._covariance(got["P"], got["F"], got["Q"], got["HX"], got["HP"], lo, i)
    code_r = DR.covariance(want, lo, i)
    pairs: list = [(code, code_r), (got["HP"], want["HP"])]
    if code == 1:
        pairs.append((got["P"][i], want["P"][i]))
    return pairs


@case(K._fuse_latest)
def _(a):
    win, j, t_c, z0, z1, r_px, prm = a[8:]
    prm = _two(prm)
    c, f = _config(prm)
    got, want = _buf(a[:8], win), _buf(a[:8], win)
    code = K._fuse_latest(*(got[k] for k in _BUF), got["win"], j, t_c, z0, z1, r_px, prm)
    code_r = DR.fuse_latest(want, j, t_c, _v(z0, z1), r_px, c, f)
    return [(code, code_r), *_compare_buffers(got, want, int(win[0]), int(win[1]))]


@case(K._replay)
def _(a):
    hi, j, x, P0, t, mt, mz, mr, k, new_t_c, prm, last = a[8:]
    prm = _two(prm)
    c, f = _config(prm)
    got, want = _buf(a[:8]), _buf(a[:8])
    last_k, last_r = last.copy(), last.copy()
    ok = K._replay(*(got[n] for n in _BUF), hi, j, x.copy(), P0.copy(), t, mt, mz, mr, k,
                   new_t_c, prm, last_k)  # fmt: skip
    meas = [(mt[i], mz[i], mr[i]) for i in range(len(mt))]
    ok_r = DR.replay(want, hi, j, x, P0, t, meas, k, new_t_c, last_r, c, f)
    return [(ok, ok_r), (last_k, last_r), *_compare_buffers(got, want, j + 1, hi)]


@case(K._predict)
def _(a):
    win, tracking, time_s, horizon, gyro, v_c, R_WC, R_CB, prm = a[8:]
    prm = _two(prm)
    c, f = _config(prm)
    got, want = _buf(a[:8], win), _buf(a[:8], win)
    code = K._predict(*(got[n] for n in _BUF), got["win"], tracking, time_s, horizon,
                      gyro.copy(), v_c.copy(), R_WC.copy(), R_CB, prm)  # fmt: skip
    code_r = DR.predict(
        want, tracking, time_s, horizon, gyro, v_c if v_c.shape == (3,) else None,
        R_WC if R_WC.shape == (3, 3) else None, R_CB.reshape(3, 3), c, f,
    )  # fmt: skip
    hi = int(win[1]) + 1
    pairs = [(code, code_r), (got["win"], want["win"])]
    return pairs + _compare_buffers(got, want, int(win[0]), hi)


@case(K._bisect_right)
def _(a):
    arr, lo, hi, t = a
    return [(K._bisect_right(*_copy(a)), bisect.bisect_right(arr, t, lo, hi))]


@case(K._view)
def _(a):
    T, U, X, HX, win, tracking, last, timeout, f, at_given, at_s = a
    buf = {"T": T, "U": U, "X": X, "HX": HX, "win": win}
    want = DR.view(buf, tracking, last, timeout, f, at_s if at_given else None)
    return [(K._view(*_copy(a)), want)]
