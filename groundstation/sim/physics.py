"""The simulator's physics as compiled kernels (:mod:`onboard.jit`): the multicopter's step,
the wind (gusts, the fan jet's profile) and :func:`physics_steps`, which runs every physics
step between two events (camera frame, control tick, command arrival) in one call: vehicle,
target (:func:`.target_kernels.target_step`) and wind, then the closest approach inside the
step and the outcome. The Python classes (:class:`~.vehicle.Multicopter`,
:class:`~.targets.Target`, :class:`~.wind.Wind`) keep their state in float64 arrays these
kernels update in place.

numba's on-disk cache is keyed on the source file of the function it compiled, so a kernel
that calls a kernel of another file names it in its ``uses`` (onboard/jit.py): an edit to
the callee then drops the caller's cached code. The arithmetic is the Python code's,
operation for operation (no fast-math): ``x ** 2`` is libm's ``pow`` in Python, so the
kernels call ``math.pow(x, two)`` with ``two`` = 2.0 passed in at run time (a constant 2
would be folded into ``x * x``, which rounds differently in about 0.1 % of cases).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from onboard.datatypes import GRAVITY_M_S2
from onboard.jit import kernel

from ..scenario.physics import AIR_DENSITY_KG_M3, helium_gross_lift_n
from .target_kernels import KIND_BALLOON, KIND_TETHERED, T_SIZE, TX_SIZE, target_step

# what these kernels read from other files (their cache is dropped when one changes): the air
# density of scenario/physics.py, the targets' kernel
_USES = (helium_gross_lift_n,)
_USES_STEPS = (helium_gross_lift_n, target_step)

PASS_RADIUS_M = 3.0  # a closest approach nearer than this is the pass once range opens
DIVERGED_SPEED_M_S = 60.0
_DIVERGED_SPEED2 = DIVERGED_SPEED_M_S**2  # (m/s)^2, compared with |v|^2 at every step

# the state array Multicopter.x: position, velocity (m, m/s ENU), attitude (w, x, y, z body
# -> world), body rates (rad/s FLU), kinematic acceleration of the last step (m/s^2),
# achieved thrust (N), commanded rates and thrust, body rates summed since the last gyro read
# and how many steps that sum holds
X_P, X_V, X_Q, X_W, X_ACC, X_THRUST = 0, 3, 6, 10, 13, 16
X_CMD_W, X_CMD_THRUST, X_RATE_SUM, X_RATE_N = 17, 20, 21, 24
X_SIZE = 25
# the per-step-size constants Multicopter.lag(dt): rate lag, thrust lag, linear drag / mass
# (1/s), mass (kg), body drag 0.5 rho C_d A / mass (1/m), rotor drag per unit thrust / mass
# (1/(s N)): the airframe of this sortie (vehicle.py), and its rotors' disc area (m^2, the
# downwash; 0: none)
L_RATE, L_THRUST, L_DRAG, L_MASS, L_BODY, L_ROTOR, L_DISC = 0, 1, 2, 3, 4, 5, 6
L_SIZE = 7


@kernel("UniTuple(f8, 3)(f8, f8, f8, f8)")
def thrust_axis(qw: float, qx: float, qy: float, qz: float) -> tuple[float, float, float]:
    """Body z (the thrust axis) in the world of the attitude (qw, qx, qy, qz) (body -> world)."""
    return 2.0 * (qx * qz + qw * qy), 2.0 * (qy * qz - qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy)


@kernel("f8(f8[::1], f8[::1], f8, f8, f8, f8)")
def vehicle_step(
    x: np.ndarray, lag: np.ndarray, dt: float, wx: float, wy: float, wz: float
) -> float:
    """Advance the state ``x`` (X_* layout) one step of ``dt`` (s) in the wind (wx, wy, wz)
    (m/s ENU, where the vehicle is at the start of the step), in place; return the sum of
    position, velocity, attitude and body rates after it (finite iff they all are).

    Drag on the air-relative velocity v_a = v - wind (``lag``, L_* layout): linear
    -k v_a, body -b |v_a| v_a, rotor -r T (v_a - (v_a . z_B) z_B) (the rotor plane's part,
    proportional to the thrust T)."""
    aw, at, kd, mass = lag[0], lag[1], lag[2], lag[3]
    kb, kr = lag[4], lag[5]
    w0, w1, w2 = x[10], x[11], x[12]
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    vx, vy, vz = x[3], x[4], x[5]
    px, py, pz = x[0], x[1], x[2]
    thrust_n = x[16]
    w0 += (x[17] - w0) * aw
    w1 += (x[18] - w1) * aw
    w2 += (x[19] - w2) * aw
    x[21] += w0
    x[22] += w1
    x[23] += w2
    x[24] += 1.0
    thrust_n += (x[20] - thrust_n) * at
    # attitude: q <- q (x) exp(w dt / 2)
    rate = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    ang = rate * dt
    if ang > 1e-12:
        h = 0.5 * ang
        sh = math.sin(h) / (ang / dt)
        dw, dx, dy, dz = math.cos(h), w0 * sh, w1 * sh, w2 * sh
        qw, qx, qy, qz = (
            qw * dw - qx * dx - qy * dy - qz * dz,
            qw * dx + qx * dw + qy * dz - qz * dy,
            qw * dy - qx * dz + qy * dw + qz * dx,
            qw * dz + qx * dy - qy * dx + qz * dw,
        )
        n = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw, qx, qy, qz = qw * n, qx * n, qy * n, qz * n
    # thrust axis z_B in the world
    ft = thrust_n / mass
    zx, zy, zz = thrust_axis(qw, qx, qy, qz)
    rx, ry, rz = vx - wx, vy - wy, vz - wz  # air-relative velocity
    air = math.sqrt(rx * rx + ry * ry + rz * rz)
    along = rx * zx + ry * zy + rz * zz
    k = kd + kb * air
    kt = kr * thrust_n
    ax = ft * zx - k * rx - kt * (rx - along * zx)
    ay = ft * zy - k * ry - kt * (ry - along * zy)
    az = ft * zz - k * rz - kt * (rz - along * zz) - GRAVITY_M_S2
    vx += ax * dt
    vy += ay * dt
    vz += az * dt
    px, py, pz = px + vx * dt, py + vy * dt, pz + vz * dt
    x[0], x[1], x[2] = px, py, pz
    x[3], x[4], x[5] = vx, vy, vz
    x[6], x[7], x[8], x[9] = qw, qx, qy, qz
    x[10], x[11], x[12] = w0, w1, w2
    x[13], x[14], x[15] = ax, ay, az
    x[16] = thrust_n
    return px + py + pz + vx + vy + vz + qw + qx + qy + qz + w0 + w1 + w2


@kernel("UniTuple(f8, 3)(f8[::1])")
def gyro_mean(x: np.ndarray) -> tuple[float, float, float]:
    """The mean body rate (rad/s FLU) of the steps since the last read, from the sums the
    steps keep in the state ``x`` (what averaging the IMU's samples yields), which it zeroes;
    the body rate now if no step ran since."""
    n = x[X_RATE_N]
    if n == 0.0:
        return x[X_W], x[X_W + 1], x[X_W + 2]
    s0, s1, s2 = x[X_RATE_SUM], x[X_RATE_SUM + 1], x[X_RATE_SUM + 2]
    x[X_RATE_SUM] = x[X_RATE_SUM + 1] = x[X_RATE_SUM + 2] = x[X_RATE_N] = 0.0
    return s0 / n, s1 / n, s2 / n


@kernel("UniTuple(f8, 2)(f8[::1])")
def normal_accel(x: np.ndarray) -> tuple[float, float]:
    """The vehicle's actual acceleration normal to its velocity (m/s^2) from its state ``x``
    (the last step's kinematic acceleration), and |v|^2 (m^2/s^2); below 1e-9 m^2/s^2 the
    whole acceleration."""
    a0, a1, a2 = x[X_ACC], x[X_ACC + 1], x[X_ACC + 2]
    v0, v1, v2 = x[X_V], x[X_V + 1], x[X_V + 2]
    vv = v0 * v0 + v1 * v1 + v2 * v2
    av = a0 * v0 + a1 * v1 + a2 * v2
    aa = a0 * a0 + a1 * a1 + a2 * a2
    return math.sqrt(max(aa - (av * av / vv if vv > 1e-9 else 0.0), 0.0)), vv


@kernel("void(f8[::1], f8, f8, f8, f8, f8, f8)")
def vehicle_command(
    x: np.ndarray, max_rate: float, max_thrust_n: float, c0: float, c1: float, c2: float, t: float
) -> None:
    """Command body rates (c0, c1, c2) (rad/s FLU, clamped to ``max_rate`` per axis) and
    normalised thrust ``t`` (clamped to [0, 1], times ``max_thrust_n``) into the state ``x``:
    they take effect at the next step. A NaN stays NaN."""
    lim = max_rate
    # min(max(c, -lim), lim) per axis, written out
    if c0 < -lim:
        c0 = -lim
    if c0 > lim:
        c0 = lim
    if c1 < -lim:
        c1 = -lim
    if c1 > lim:
        c1 = lim
    if c2 < -lim:
        c2 = -lim
    if c2 > lim:
        c2 = lim
    if t < 0.0:  # min(max(t, 0.0), 1.0)
        t = 0.0
    if t > 1.0:
        t = 1.0
    x[17], x[18], x[19] = c0, c1, c2
    x[20] = t * max_thrust_n


# the wind's parameter array Wind.params: the mean (m/s), the gusts' sigmas per axis (m/s),
# the time now (s), the number of turbulence modes, 1.0 for the fan jet (0.0 uniform), the
# jet's profile at the reference point, the fan's outlet centre (m) and diameter (m)
W_MEAN, W_SIGMA, W_TIME, W_NMODES, W_JET, W_REF, W_SOURCE, W_DIA = 0, 3, 6, 7, 8, 9, 10, 13
W_SIZE = 14
# a turbulence mode Wind.modes row: wavenumber (rad/m, ENU), cosine and sine amplitudes
M_K, M_C, M_S = 0, 3, 6
M_SIZE = 9
JET_DECAY_B = 5.8  # U_c / U_0 = B D / x (Hussein et al. 1994; Pope Table 5.1)
JET_SPREAD_S = 0.094  # r_1/2 = S x
_LN2 = math.log(2.0)


@kernel("f8(f8, f8, f8, f8, f8, f8, f8, f8, f8, f8, b1)")
def jet_factor(
    m0: float,
    m1: float,
    m2: float,
    s0: float,
    s1: float,
    s2: float,
    dia: float,
    px: float,
    py: float,
    pz: float,
    on_axis: bool,
) -> float:
    """U(x, r) / U_0 of the fan jet of mean (m0, m1, m2) (m/s) from the outlet (s0, s1, s2)
    of diameter ``dia`` (m) at (px, py, pz) (m, ENU), or with ``on_axis`` U_c(x) / U_0 at
    p's distance along the axis; 0 behind the fan or without a mean (wind.py's model)."""
    speed = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    if speed <= 0.0:
        return 0.0
    d0, d1, d2 = px - s0, py - s1, pz - s2
    x = (d0 * m0 + d1 * m1 + d2 * m2) / speed
    if x <= 0.0:
        return 0.0
    core = JET_DECAY_B * dia / x
    if not core < 1.0:  # min(1.0, core)
        core = 1.0
    if on_axis:
        return core
    r2 = d0 * d0 + d1 * d1 + d2 * d2 - x * x
    if r2 < 0.0:  # max(r2, 0.0)
        r2 = 0.0
    r_half = 0.5 * dia
    if JET_SPREAD_S * x > r_half:  # max(0.5 D, S x)
        r_half = JET_SPREAD_S * x
    return core * math.exp(-_LN2 * r2 / (r_half * r_half))


@kernel("UniTuple(f8, 3)(f8[::1], f8[:, ::1], f8, f8, f8)")
def turbulence_at(c: np.ndarray, modes: np.ndarray, px: float, py: float, pz: float) -> tuple:
    """The turbulence (m/s ENU, before the jet's profile) at (px, py, pz) (m) at the time
    c[W_TIME]: the frozen field of ``modes`` (M_* rows, unit variance per axis) carried by the
    mean wind (Taylor's hypothesis), times the sigmas per axis (wind.py)."""
    n = min(int(c[7]), modes.shape[0])  # never past the modes given
    if n <= 0:
        return 0.0, 0.0, 0.0
    t = c[6]
    m = modes[:n]
    # all modes at once: plain Python runs a few numpy operations instead of a loop over ~100
    # modes at every physics step. Each sum is taken in order (cumsum; numpy's sum pairs its
    # terms), as the compiled kernel sums, so the two agree bit for bit
    th = m[:, 0] * (px - c[0] * t) + m[:, 1] * (py - c[1] * t) + m[:, 2] * (pz - c[2] * t)
    cs, sn = np.cos(th), np.sin(th)
    g0 = (m[:, 3] * cs + m[:, 6] * sn).cumsum()[-1]
    g1 = (m[:, 4] * cs + m[:, 7] * sn).cumsum()[-1]
    g2 = (m[:, 5] * cs + m[:, 8] * sn).cumsum()[-1]
    return c[3] * g0, c[4] * g1, c[5] * g2


@kernel("UniTuple(f8, 3)(f8[::1], f8[:, ::1], f8, f8, f8)")
def wind_at(c: np.ndarray, modes: np.ndarray, px: float, py: float, pz: float) -> tuple:
    """The wind now (m/s ENU) at (px, py, pz) (m): the mean plus the turbulence there
    (:func:`turbulence_at`), for the jet times its profile relative to the reference point."""
    g0, g1, g2 = turbulence_at(c, modes, px, py, pz)
    w0, w1, w2 = c[0] + g0, c[1] + g1, c[2] + g2
    if c[8] == 0.0:
        return w0, w1, w2
    f = jet_factor(c[0], c[1], c[2], c[10], c[11], c[12], c[13], px, py, pz, False) / c[9]
    return f * w0, f * w1, f * w2


@kernel("UniTuple(f8, 3)(f8[::1], f8[::1], f8, f8, f8, f8, f8, f8)", uses=_USES)
def rotor_wash_at(
    x: np.ndarray, lag: np.ndarray, wx: float, wy: float, wz: float, px: float, py: float, pz: float
) -> tuple:
    """The air the vehicle's rotors push (m/s ENU) at (px, py, pz) (m), from the vehicle's
    state ``x`` (X_*), its airframe ``lag`` (L_*) and the wind (wx, wy, wz) where it is.

    Momentum theory: hover induced velocity v_h = sqrt(T / (2 rho A)); in edgewise flight at
    the airspeed V in the rotor plane v_i^2 = (sqrt(V^4 + 4 v_h^4) - V^2) / 2 (Glauert); the
    fully developed slipstream moves at 2 v_i along -z_B through a disc of the rotors' area
    contracted by 1/sqrt(2), and spreads and decays beyond as a round turbulent jet
    (:func:`jet_factor`) whose axis is the slipstream's path relative to the vehicle,
    -2 v_i z_B - v_air (a fast vehicle leaves its wake behind it). Nothing above the rotors."""
    area = lag[6]
    thrust = x[16]
    if area <= 0.0 or thrust <= 0.0:
        return 0.0, 0.0, 0.0
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    zx, zy, zz = thrust_axis(qw, qx, qy, qz)
    ax, ay, az = x[3] - wx, x[4] - wy, x[5] - wz
    along = ax * zx + ay * zy + az * zz
    ex, ey, ez = ax - along * zx, ay - along * zy, az - along * zz
    vv = ex * ex + ey * ey + ez * ez  # edgewise airspeed squared
    vh2 = thrust / (2.0 * AIR_DENSITY_KG_M3 * area)
    vi = math.sqrt(0.5 * (math.sqrt(vv * vv + 4.0 * vh2 * vh2) - vv))
    u = 2.0 * vi
    m0, m1, m2 = -u * zx - ax, -u * zy - ay, -u * zz - az  # the slipstream's axis
    dia = math.sqrt(4.0 * area / math.pi) / math.sqrt(2.0)
    f = jet_factor(m0, m1, m2, x[0], x[1], x[2], dia, px, py, pz, False)
    return -u * f * zx, -u * f * zy, -u * f * zz


@kernel("UniTuple(f8, 7)(f8, f8, f8, f8, f8, f8)")
def closest_approach(
    r0x: float, r0y: float, r0z: float, r1x: float, r1y: float, r1z: float
) -> tuple:
    """Closest approach within one physics step, the relative position moving linearly from
    r0 to r1 (target minus vehicle, m): (distance, fraction of the step, the relative
    position there (3), r0 . (r1 - r0), r1 . (r1 - r0)); the range was closing at the start
    iff the first dot product is negative and is opening at the end iff the second is
    positive."""
    d0, d1, d2 = r1x - r0x, r1y - r0y, r1z - r0z
    dd = d0 * d0 + d1 * d1 + d2 * d2
    r0d = r0x * d0 + r0y * d1 + r0z * d2
    if dd > 0.0:  # min(max(-r0d / dd, 0.0), 1.0)
        s = -r0d / dd
        if s < 0.0:
            s = 0.0
        elif s > 1.0:
            s = 1.0
    else:
        s = 0.0
    c0, c1, c2 = r0x + s * d0, r0y + s * d1, r0z + s * d2
    dist = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    return dist, s, c0, c1, c2, r0d, r1x * d0 + r1y * d1 + r1z * d2


# the simulator's outcome state Simulation.closest: relative position (target minus vehicle,
# m) at the end of the last step, closest approach so far (m), its time (s), the vehicle's
# speed then (m/s), the relative position and the vehicle's velocity then, the outcome code
# (OUTCOME_* below), the hit radius (m), the exponent 2.0 (see the module's docstring) and
# 1.0 when the last step ended closing (the range still falling at its end)
C_REL, C_MISS, C_TIME, C_SPEED, C_CLOSE_REL, C_CLOSE_VEL, C_OUTCOME, C_HIT_R, C_TWO = (
    0,
    3,
    4,
    5,
    6,
    9,
    12,
    13,
    14,
)
C_ENDED_CLOSING = 15
# after the pass: its outcome so far (OUTCOME_HIT or OUTCOME_MISS; 0 before it), its time (s)
# and the lowest altitude since (m); the sortie goes on until the vehicle has recovered
C_PASS, C_PASS_TIME, C_MIN_ALT = 16, 17, 18
C_SIZE = 19
OUTCOME_NONE, OUTCOME_HIT, OUTCOME_MISS, OUTCOME_DIVERGED, OUTCOME_CRASHED = 0, 1, 2, 3, 4


# One sortie's physics in one array (so that a kernel call passes one array, not a dozen):
# the vehicle's state and constants, the target's constants and state, the wind's constants
# (its turbulence modes are the kernel's own argument), the closest approach and outcome,
# the command on its way to the actuators (the step it arrives at, -1 for none; body rates
# rad/s FLU, normalised thrust; the rate limit rad/s and the maximum thrust N), the target's
# kind and the step (s). The objects' arrays
# become views into it (:func:`sortie_buffer`).
S_VX = 0
S_LAG = S_VX + X_SIZE
S_TC = S_LAG + L_SIZE
S_TX = S_TC + T_SIZE
S_WC = S_TX + TX_SIZE
S_CS = S_WC + W_SIZE
S_CMD = S_CS + C_SIZE
S_KIND = S_CMD + 7
S_DT = S_KIND + 1
S_SIZE = S_DT + 1


def sortie_buffer(vehicle: Any, target: Any, wind: Any, dt: float) -> np.ndarray:
    """The S_* array for one sortie of ``vehicle`` (:class:`~.vehicle.Multicopter`),
    ``target`` (:class:`~.targets.Target`) and ``wind`` (:class:`~.wind.Wind`) in steps of
    ``dt`` (s): their state and constant arrays are copied in and replaced by views into it,
    so they read and write the same numbers :func:`physics_steps` does. The closest-approach
    part starts zero (the caller fills it)."""
    buf = np.zeros(S_SIZE)
    for obj, name, at, size in (
        (vehicle, "x", S_VX, X_SIZE),
        (target, "params", S_TC, T_SIZE),
        (target, "x", S_TX, TX_SIZE),
        (wind, "params", S_WC, W_SIZE),
    ):
        view = buf[at : at + size]
        view[:] = getattr(obj, name)
        setattr(obj, name, view)
    buf[S_LAG : S_LAG + L_SIZE] = vehicle.lag(dt)
    buf[S_CMD] = -1.0
    buf[S_CMD + 5], buf[S_CMD + 6] = vehicle.max_rate_rad_s, vehicle.params.max_thrust_n
    buf[S_KIND], buf[S_DT] = target.kind, dt
    return buf


@kernel("i8(i8, i8, f8[::1], f8[:, ::1], f8[:, ::1])", uses=_USES_STEPS)
def physics_steps(k0: int, n: int, buf: np.ndarray, track: np.ndarray, modes: np.ndarray) -> int:
    """Integrate the vehicle, target and wind of ``buf`` (S_* layout; ``track`` rows for a
    recorded target track) from step ``k0`` (time k0 dt, s) over ``n`` steps in the wind
    with the turbulence ``modes`` (M_* rows); the command in ``buf`` reaches the vehicle at
    the start of its step. Each body feels the wind where it is at the start of the step; a
    light target (tethered, balloon) the vehicle's rotor wash too; a manoeuvring target sees
    where the vehicle is at the end of the step (jink, evade). After each step, the
    closest approach inside it in continuous time (relative motion linear over the step) and
    the outcome; stop at an outcome. Return the number of steps taken."""
    vx = buf[S_VX : S_VX + X_SIZE]
    lag = buf[S_LAG : S_LAG + L_SIZE]
    tc = buf[S_TC : S_TC + T_SIZE]
    tx = buf[S_TX : S_TX + TX_SIZE]
    wc = buf[S_WC : S_WC + W_SIZE]
    cs = buf[S_CS : S_CS + C_SIZE]
    dt = buf[S_DT]
    kind = int(buf[S_KIND])
    light = kind in (KIND_TETHERED, KIND_BALLOON)  # moved by the air
    two = cs[14]
    hit_r = cs[13]
    miss = cs[3]
    r0x, r0y, r0z = cs[0], cs[1], cs[2]
    for k in range(k0, k0 + n):
        t = k * dt
        wc[W_TIME] = t
        due = buf[S_CMD]
        if due >= 0.0 and due <= k:  # the command reaches the actuators
            c = S_CMD
            vehicle_command(
                vx, buf[c + 5], buf[c + 6], buf[c + 1], buf[c + 2], buf[c + 3], buf[c + 4]
            )
            buf[S_CMD] = -1.0
        w0, w1, w2 = wind_at(wc, modes, vx[0], vx[1], vx[2])
        if light:
            # the air at the target: the wind there and the wash of the vehicle's rotors
            a0, a1, a2 = wind_at(wc, modes, tx[0], tx[1], tx[2])
            b0, b1, b2 = rotor_wash_at(vx, lag, w0, w1, w2, tx[0], tx[1], tx[2])
            a0, a1, a2 = a0 + b0, a1 + b1, a2 + b2
        fin = vehicle_step(vx, lag, dt, w0, w1, w2)
        px, py, pz = vx[0], vx[1], vx[2]
        vvx, vvy, vvz = vx[3], vx[4], vx[5]
        if light:
            target_step(kind, tc, track, tx, t + dt, dt, a0, a1, a2, px, py, pz)
        elif kind != 0:
            target_step(kind, tc, track, tx, t + dt, dt, 0.0, 0.0, 0.0, px, py, pz)
        # closest approach inside the step just taken, then hit/miss, divergence and ground
        r1x, r1y, r1z = tx[0] - px, tx[1] - py, tx[2] - pz
        dist, s, c0, c1, c2, r0d, r1d = closest_approach(r0x, r0y, r0z, r1x, r1y, r1z)
        r0x, r0y, r0z = r1x, r1y, r1z
        cs[0], cs[1], cs[2] = r1x, r1y, r1z
        passed = cs[C_PASS] != 0.0
        if not passed and dist < miss:
            miss = dist
            cs[3] = dist
            cs[4] = t + s * dt
            cs[5] = math.sqrt(math.pow(vvx, two) + math.pow(vvy, two) + math.pow(vvz, two))
            cs[6], cs[7], cs[8] = c0, c1, c2
            cs[9], cs[10], cs[11] = vvx, vvy, vvz
        outcome = OUTCOME_NONE
        closing = r0d < 0.0 or cs[C_ENDED_CLOSING] != 0.0
        cs[C_ENDED_CLOSING] = 1.0 if r1d < 0.0 else 0.0
        if passed:
            cs[C_MIN_ALT] = min(cs[C_MIN_ALT], pz)
        elif dist < PASS_RADIUS_M and closing and r1d > 0.0:
            # closing at the start of the step (or at the end of the one before: the closest
            # point on the step boundary), opening at its end, near: the pass is over (the
            # miss is final), the sortie goes on to the recovery
            cs[C_PASS] = OUTCOME_HIT if miss <= hit_r else OUTCOME_MISS
            cs[C_PASS_TIME] = t + dt
            cs[C_MIN_ALT] = pz
        if (
            not (math.isfinite(fin) and math.isfinite(r1x + r1y + r1z))
            or vvx * vvx + vvy * vvy + vvz * vvz > _DIVERGED_SPEED2
        ):
            outcome = OUTCOME_DIVERGED
        elif pz <= 0.0:
            outcome = OUTCOME_CRASHED
        if outcome != OUTCOME_NONE:
            cs[12] = outcome
            return k - k0 + 1
    return n
