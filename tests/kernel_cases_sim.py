"""The simulator's kernels and their references (see :mod:`tests.kernel_cases`)."""

from __future__ import annotations

import math

import numpy as np

from groundstation.sim import camera as sim_camera
from groundstation.sim import estimate as sim_estimate
from groundstation.sim import estimate_reference as ER  # noqa: N812
from groundstation.sim import physics as P  # noqa: N812
from groundstation.sim import physics_reference as PR  # noqa: N812
from groundstation.sim import target_kernels as TK  # noqa: N812
from groundstation.sim import target_reference as TR  # noqa: N812
from onboard.datatypes import GRAVITY_M_S2
from tests.kernel_cases import FRESH, _copy, _v, case


@case(sim_camera.sphere_image)
def _(a):
    R_WC, c0, c1, c2, t0, t1, t2, dia, f, cu, cv = a
    pixel, r_px = PR.sphere_image(R_WC, _v(c0, c1, c2), _v(t0, t1, t2), dia, f, _v(cu, cv))
    want = (0.0, math.nan, math.nan, r_px) if pixel is None else (1.0, *pixel, r_px)
    return [(sim_camera.sphere_image(*_copy(a)), want)]


# ---------------------------------------------------------------- the simulator
def _unit(q: np.ndarray) -> np.ndarray:
    """A perturbed attitude made a unit quaternion again (the kernels' domain)."""
    return q / np.linalg.norm(q)


def _wind_params(c: np.ndarray, modes: np.ndarray) -> np.ndarray:
    """The wind's constants with their structural entries as the Wind made them (a
    perturbation must not change them): the number of modes is the rows given, the jet a
    flag."""
    c = c.copy()
    c[P.W_NMODES] = float(len(modes))
    c[P.W_JET] = 1.0 if c[P.W_JET] != 0.0 else 0.0
    return c


@case(P.thrust_axis)
def _(a):
    q = _unit(_v(*a))
    return [(P.thrust_axis(*q.tolist()), PR.thrust_axis(q))]


@case(P.vehicle_step)
def _(a):
    x, lag, dt, wx, wy, wz = a
    got = x.copy()
    total = P.vehicle_step(got, lag.copy(), dt, wx, wy, wz)
    want = PR.vehicle_step(x, PR.Airframe.of(lag), dt, _v(wx, wy, wz))
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


@case(TK.target_step)
def _(a):
    kind, c, track, x, t, dt, wx, wy, wz, ix, iy, iz = a
    got = x.copy()
    TK.target_step(kind, c.copy(), track.copy(), got, t, dt, wx, wy, wz, ix, iy, iz)
    want = TR.target_state(TK.MOTIONS[kind], c, track, x, t, dt, _v(wx, wy, wz), _v(ix, iy, iz))
    return [(got, want)]


@case(P.jet_factor)
def _(a):
    want = PR.jet_factor(_v(*a[0:3]), _v(*a[3:6]), a[6], _v(*a[7:10]), a[10])
    return [(P.jet_factor(*a), want)]


@case(P.turbulence_at)
def _(a):
    c, modes, px, py, pz = a
    c = _wind_params(c, modes)
    want = PR.turbulence_at(PR.WindParams.of(c), modes, _v(px, py, pz))
    return [(P.turbulence_at(c.copy(), modes.copy(), px, py, pz), want)]


@case(P.wind_at)
def _(a):
    c, modes, px, py, pz = a
    c = _wind_params(c, modes)
    want = PR.wind_at(PR.WindParams.of(c), modes, _v(px, py, pz))
    return [(P.wind_at(c.copy(), modes.copy(), px, py, pz), want)]


@case(P.rotor_wash_at)
def _(a):
    x, lag, wx, wy, wz, px, py, pz = a
    want = PR.rotor_wash_at(x, PR.Airframe.of(lag), _v(wx, wy, wz), _v(px, py, pz))
    return [(P.rotor_wash_at(*_copy(a)), want)]


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
    """A target_step call of any motion (a sortie flies only some of them): kinematic
    parameters at random, a light target's of a sphere 0.1-0.5 m across (C_d 0.47, with or
    without buffet), starting near the ground (some below it) in air of a few m/s; a
    manoeuvre's side +-1, its direction a unit vector, triggered or not (half each, with the
    interceptor within or beyond the trigger range, one in ten unknown: nan)."""
    kind = int(rng.integers(0, len(TK.MOTIONS)))
    c = rng.normal(size=TK.T_SIZE) * 3.0
    c[TK.T_MAX_SPEED], c[TK.T_ROPE] = 4.0, 5.0
    c[TK.T_TWO] = 2.0
    dia = float(rng.uniform(0.1, 0.5))
    area = math.pi * dia * dia / 4.0
    c[TK.T_DIA], c[TK.T_AREA] = dia, area
    c[TK.T_DRAG_K] = 0.5 * TR.RHO * 0.47 * area
    c[TK.T_LIFT], c[TK.T_MASS] = float(rng.uniform(-0.05, 0.05)), float(rng.uniform(0.003, 0.2))
    c[TK.T_CL] = float(rng.uniform(0.05, 0.2)) if rng.uniform() < 0.8 else 0.0
    c[TK.T_STROUHAL] = float(rng.uniform(0.1, 0.3))
    c[TK.T_SIDE] = 1.0 if rng.uniform() < 0.5 else -1.0
    c[TK.T_TRIGGER] = float(rng.uniform(-2.0, 15.0))
    c[TK.T_JINK_SPEED], c[TK.T_JINK_ACCEL] = float(rng.uniform(0.5, 4.0)), 8.0
    c[TK.T_MAN_W] = float(rng.uniform(0.3, 3.0))
    d = rng.normal(size=3)
    c[TK.T_DIR : TK.T_DIR + 3] = d / np.linalg.norm(d)
    times = np.sort(rng.uniform(0.0, 10.0, 6))
    track = np.column_stack([times, rng.normal(size=(6, 3)) * 10.0])
    x = np.zeros(TK.TX_SIZE)
    x[:6] = rng.normal(size=6) * 2.0
    x[2] += 1.0
    x[TK.TX_PHASE] = rng.uniform(0.0, 2.0 * math.pi)
    if rng.uniform() < 0.5:  # a manoeuvre under way
        x[TK.TX_TRIGGERED] = 1.0
        side = rng.normal(size=2)
        x[TK.TX_DIR : TK.TX_DIR + 2] = side / np.linalg.norm(side)
        x[TK.TX_GAINED] = float(rng.uniform(0.0, 3.0))
    air = (rng.normal(size=3) * 3.0).tolist()
    near = x[:3] + rng.normal(size=3) * float(rng.uniform(1.0, 20.0))
    interceptor = [math.nan] * 3 if rng.uniform() < 0.1 else near.tolist()
    return (kind, c, track, x, float(rng.uniform(0, 12)), 0.005, *air, *interceptor)


def _fresh_rotor_wash(rng: np.random.Generator) -> tuple:
    """A rotor_wash_at call (a recorded sortie's balloon is rarely in the wash): a vehicle of
    0.5-2 kg tilted up to about 30 degrees, at 0.3-2 times its hover thrust, 0.02-0.2 m^2 of
    rotor discs, flying at a few m/s in a few m/s of wind; the point 5 cm to 5 m down its
    thrust axis and up to about a metre aside, one in ten above the rotors."""
    mass = float(rng.uniform(0.5, 2.0))
    x = np.zeros(P.X_SIZE)
    x[P.X_P : P.X_P + 3] = rng.normal(size=3) * 3.0 + (0.0, 0.0, 5.0)
    x[P.X_V : P.X_V + 3] = rng.normal(size=3) * 3.0
    q = np.concatenate([[1.0], rng.normal(size=3) * 0.3])
    x[P.X_Q : P.X_Q + 4] = q / np.linalg.norm(q)
    x[P.X_THRUST] = mass * GRAVITY_M_S2 * float(rng.uniform(0.3, 2.0))
    lag = np.zeros(P.L_SIZE)
    lag[P.L_RATE], lag[P.L_THRUST], lag[P.L_MASS] = 0.2, 0.1, mass
    lag[P.L_BODY], lag[P.L_ROTOR] = 0.005, 0.01
    lag[P.L_DISC] = float(rng.uniform(0.02, 0.2))
    z_B = PR.thrust_axis(x[P.X_Q : P.X_Q + 4])
    down = float(rng.uniform(0.05, 5.0)) * (-1.0 if rng.uniform() < 0.1 else 1.0)
    p = x[P.X_P : P.X_P + 3] - down * z_B + rng.normal(size=3) * 0.3 * abs(down)
    wind = (rng.normal(size=3) * 2.0).tolist()
    return (x, lag, *wind, *p.tolist())


FRESH["groundstation.sim.target_kernels.target_step"] = _fresh_target
FRESH["groundstation.sim.physics.rotor_wash_at"] = _fresh_rotor_wash
