"""The simulator's kernels and their references (see :mod:`tests.kernel_cases`)."""

from __future__ import annotations

import math

import numpy as np

from groundstation.sim import camera as sim_camera
from groundstation.sim import estimate as sim_estimate
from groundstation.sim import estimate_reference as ER  # noqa: N812
from groundstation.sim import physics as P  # noqa: N812
from groundstation.sim import physics_reference as PR  # noqa: N812
from tests.kernel_cases import FRESH, _copy, _v, case


@case(sim_camera.sphere_image)
def _(a):
    R_WC, c0, c1, c2, t0, t1, t2, dia, f, cu, cv = a
    pixel, r_px = PR.sphere_image(R_WC, _v(c0, c1, c2), _v(t0, t1, t2), dia, f, _v(cu, cv))
    want = (0.0, math.nan, math.nan, r_px) if pixel is None else (1.0, *pixel, r_px)
    return [(sim_camera.sphere_image(*_copy(a)), want)]


# ---------------------------------------------------------------- the simulator
@case(P.vehicle_step)
def _(a):
    x, lag, dt, wx, wy, wz = a
    got = x.copy()
    total = P.vehicle_step(got, lag.copy(), dt, wx, wy, wz)
    want = PR.vehicle_step(x, *lag, dt, _v(wx, wy, wz))
    return [(got, want), (total, float(np.sum(want[: P.X_W + 3])))]


@case(P.gyro_mean)
def _(a):
    return [(P.gyro_mean(a[0].copy()), PR.gyro_mean(a[0]))]


@case(P.normal_accel)
def _(a):
    return [(P.normal_accel(a[0].copy()), PR.normal_accel(a[0]))]


@case(P.vehicle_command)
def _(a):
    x, max_rate, max_thrust, c0, c1, c2, t = a
    got = x.copy()
    P.vehicle_command(got, max_rate, max_thrust, c0, c1, c2, t)
    rates, thrust = PR.vehicle_command(_v(c0, c1, c2), t, max_rate, max_thrust)
    return [(got[P.X_CMD_W : P.X_CMD_W + 3], rates), (got[P.X_CMD_THRUST], thrust)]


@case(P.target_step)
def _(a):
    kind, c, track, x, t, dt, wx, wy, wz = a
    got = x.copy()
    P.target_step(kind, c.copy(), track.copy(), got, t, dt, wx, wy, wz)
    return [(got, PR.target_state(P.MOTIONS[kind], c, track, x, t, dt, _v(wx, wy, wz)))]


@case(P.jet_factor)
def _(a):
    want = PR.jet_factor(_v(*a[0:3]), _v(*a[3:6]), a[6], _v(*a[7:10]), a[10])
    return [(P.jet_factor(*a), want)]


@case(P.wind_at)
def _(a):
    c, modes, px, py, pz = a
    return [(P.wind_at(*_copy(a)), PR.wind_at(c, modes, _v(px, py, pz)))]


@case(P.turbulence_at)
def _(a):
    c, modes, px, py, pz = a
    return [(P.turbulence_at(*_copy(a)), PR.turbulence_at(c, modes, _v(px, py, pz)))]


@case(P.rotor_wash_at)
def _(a):
    x, lag, wx, wy, wz, px, py, pz = a
    want = PR.rotor_wash_at(x, lag[P.L_DISC], _v(wx, wy, wz), _v(px, py, pz))
    return [(P.rotor_wash_at(*_copy(a)), want)]


@case(P.thrust_axis)
def _(a):
    q = _v(*a)
    if abs(float(q @ q) - 1.0) > 1e-9:  # the formula is for a unit quaternion
        q = q / np.linalg.norm(q)
    return [(P.thrust_axis(*q), PR.thrust_axis(q))]


@case(P.closest_approach)
def _(a):
    dist, s, c, r0d, r1d = PR.closest_approach(_v(*a[:3]), _v(*a[3:]))
    return [(P.closest_approach(*a), (dist, s, *c, r0d, r1d))]


@case(P.physics_steps)
def _(a):
    k0, n, buf, track, modes = a
    got = buf.copy()
    steps = P.physics_steps(k0, n, got, track.copy(), modes.copy())
    steps_r, want = PR.physics_steps(k0, n, buf, track, modes)
    return [(steps, steps_r), (got, want)]


@case(sim_estimate.delay_push)
def _(a):
    ring, now, _out = a
    got_ring, out = ring.copy(), np.empty(len(now))
    sim_estimate.delay_push(got_ring, now.copy(), out)
    want_ring, want = ER.delay_push(ring, now)
    return [(got_ring[0], want_ring[0]), (out, want)]


@case(sim_estimate.advance_errors)
def _(a):
    t, k, x, normals = a
    got_k, got_x = k.copy(), x.copy()
    sim_estimate.advance_errors(t, got_k, got_x, normals.copy())
    want_k, want_x = ER.advance_errors(t, k, x, normals)
    return [(got_k, want_k), (got_x, want_x)]


@case(sim_estimate.estimate_of)
def _(a):
    k, x, ring, att_ring, now, _out = a
    out = np.empty(13)
    sim_estimate.estimate_of(k.copy(), x.copy(), ring.copy(), att_ring.copy(), now.copy(), out)
    return [(out, ER.estimate_of(k, x, ring, att_ring, now)[2])]


@case(sim_estimate.hand_off)
def _(a):
    t, truth, n0, n1, n2, sigma, k, x, normals, ring, att_ring, _out = a
    out = np.empty(17)
    args = _copy((t, truth, n0, n1, n2, sigma, k, x, normals, ring, att_ring))
    sim_estimate.hand_off(*args, out)
    want = ER.hand_off(t, truth, _v(n0, n1, n2), sigma, k, x, normals, ring, att_ring)
    return [(out, want)]


# ---------------------------------------------------------------- fresh arguments
def _fresh_target(rng: np.random.Generator) -> tuple:
    """A target_step call of any motion (a sortie flies only some of them)."""
    kind = int(rng.integers(0, len(P.MOTIONS)))
    c = rng.normal(size=P.T_SIZE) * 3.0
    c[P.T_MAX_SPEED], c[P.T_MASS], c[P.T_ROPE] = 4.0, 0.2, 5.0
    c[P.T_TWO] = 2.0
    c[P.T_CL], c[P.T_STROUHAL], c[P.T_DIA], c[P.T_AREA] = 0.1, 0.2, 0.16, 0.02
    times = np.sort(rng.uniform(0.0, 10.0, 6))
    track = np.column_stack([times, rng.normal(size=(6, 3)) * 10.0])
    x = rng.normal(size=P.TX_SIZE) * 2.0
    x[6] = rng.uniform(0.0, 2.0 * math.pi)
    return (kind, c, track, x, float(rng.uniform(0, 12)), 0.005, *rng.normal(size=3).tolist())


FRESH["groundstation.sim.physics.target_step"] = _fresh_target
