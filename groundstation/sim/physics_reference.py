"""The simulator's physics and camera kernels (:mod:`.physics`, :func:`.camera.sphere_image`)
written as the models are stated (DESIGN.md §6, docs/air.md): numpy vectors in world ENU,
body FLU, quaternions (w, x, y, z) body -> world, SI units. The specification the compiled
kernels are checked against (tests/test_kernel_references.py); the simulator does not call
them."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from onboard.datatypes import GRAVITY_M_S2
from onboard.geometry_reference import pixel_of, propagated_attitude, rotation_of_quaternion

from ..scenario.physics import AIR_DENSITY_KG_M3
from . import physics as P  # noqa: N812
from . import target_kernels as TK  # noqa: N812
from .target_reference import target_state

G_ENU = np.array([0.0, 0.0, -GRAVITY_M_S2])  # m/s^2
E_UP = np.array([0.0, 0.0, 1.0])
RHO = AIR_DENSITY_KG_M3  # kg/m^3, sea level, 20 C


# ---------------------------------------------------------------- the multicopter
@dataclass(frozen=True)
class Airframe:
    """The per-step constants of :meth:`.vehicle.Multicopter.lag` (the kernels' L_* array),
    by name."""

    rate_lag: float  # 1 - exp(-dt / tau_rate): the body rates' first-order lag per step
    thrust_lag: float  # 1 - exp(-dt / tau_thrust)
    linear_drag_1_s: float  # k / m, k the linear drag (N s/m)
    mass_kg: float
    body_drag_1_m: float  # 0.5 rho C_d A / m (1/m)
    rotor_drag_1_s_n: float  # k_r / (m T_hover) (1/(s N)): the rotor drag per unit thrust
    disc_area_m2: float  # all rotors' discs (0: no downwash)

    @classmethod
    def of(cls, lag: np.ndarray) -> Airframe:
        return cls(
            rate_lag=float(lag[P.L_RATE]),
            thrust_lag=float(lag[P.L_THRUST]),
            linear_drag_1_s=float(lag[P.L_DRAG]),
            mass_kg=float(lag[P.L_MASS]),
            body_drag_1_m=float(lag[P.L_BODY]),
            rotor_drag_1_s_n=float(lag[P.L_ROTOR]),
            disc_area_m2=float(lag[P.L_DISC]),
        )


def thrust_axis(q: np.ndarray) -> np.ndarray:
    """z_B = R(q) e_z, the thrust axis in the world, for a unit quaternion q."""
    return rotation_of_quaternion(q)[:, 2]


def airframe_accel(thrust_n: float, z_B: np.ndarray, v_air: np.ndarray, a: Airframe) -> np.ndarray:
    """The multicopter's acceleration (m/s^2 ENU) at thrust T (N) along z_B with the
    air-relative velocity v_a = v - w (m/s):

        a = (T / m) z_B - (k / m) v_a - (0.5 rho C_d A / m) |v_a| v_a
            - (k_r / (m T_hover)) T (v_a - (v_a . z_B) z_B) + g

    linear drag, quadratic body drag, and the rotor drag (blade flapping and induced drag: a
    force in the rotor plane, linear in the air velocity there and proportional to the thrust;
    Faessler, Franchi & Scaramuzza, IEEE RA-L 3(2), 2018; Kai et al., IFAC 2017;
    docs/air.md)."""
    in_plane = v_air - float(v_air @ z_B) * z_B
    return (
        thrust_n / a.mass_kg * z_B
        - a.linear_drag_1_s * v_air
        - a.body_drag_1_m * float(np.linalg.norm(v_air)) * v_air
        - a.rotor_drag_1_s_n * thrust_n * in_plane
        + G_ENU
    )


def vehicle_step(x: np.ndarray, a: Airframe, dt: float, wind: np.ndarray) -> np.ndarray:
    """One rigid-body step of dt (s) in the wind w (m/s, where the vehicle is at the start of
    the step); the state x in the X_* layout, returned as a new array:

        omega <- omega + (omega_cmd - omega) (1 - exp(-dt / tau_rate))   (first-order actuators)
        T     <- T + (T_cmd - T) (1 - exp(-dt / tau_thrust))
        q     <- q (x) exp(omega dt), renormalised
        v     <- v + a(T, z_B(q), v - w) dt,  p <- p + v dt            (semi-implicit Euler)

    with :func:`airframe_accel`; the step's acceleration is kept, and the rates are summed
    for the gyro's mean."""
    x = x.copy()
    omega = x[P.X_W : P.X_W + 3]
    omega = omega + (x[P.X_CMD_W : P.X_CMD_W + 3] - omega) * a.rate_lag
    thrust = x[P.X_THRUST] + (x[P.X_CMD_THRUST] - x[P.X_THRUST]) * a.thrust_lag
    x[P.X_RATE_SUM : P.X_RATE_SUM + 3] += omega
    x[P.X_RATE_N] += 1.0
    q = x[P.X_Q : P.X_Q + 4]
    if float(np.linalg.norm(omega)) * dt > 1e-12:
        q = propagated_attitude(q, omega, dt)
    v = x[P.X_V : P.X_V + 3]
    acc = airframe_accel(thrust, thrust_axis(q), v - wind, a)
    v = v + acc * dt
    x[P.X_P : P.X_P + 3] += v * dt
    x[P.X_V : P.X_V + 3] = v
    x[P.X_Q : P.X_Q + 4] = q
    x[P.X_W : P.X_W + 3] = omega
    x[P.X_ACC : P.X_ACC + 3] = acc
    x[P.X_THRUST] = thrust
    return x


def gyro_mean(x: np.ndarray) -> np.ndarray:
    """The mean body rate since the last read (the IMU's averaged samples); the rate now if
    no step ran since."""
    n = x[P.X_RATE_N]
    return x[P.X_W : P.X_W + 3] if n == 0 else x[P.X_RATE_SUM : P.X_RATE_SUM + 3] / n


def normal_accel(x: np.ndarray) -> tuple[float, float]:
    """(|a - (a . v^) v^|, |v|^2) of the last step's acceleration a and velocity v (all of a
    below |v|^2 = 1e-9)."""
    a, v = x[P.X_ACC : P.X_ACC + 3], x[P.X_V : P.X_V + 3]
    vv = float(v @ v)
    along2 = float(a @ v) ** 2 / vv if vv > 1e-9 else 0.0
    return math.sqrt(max(float(a @ a) - along2, 0.0)), vv


def vehicle_command(
    rates: np.ndarray, thrust: float, max_rate: float, max_thrust_n: float
) -> tuple[np.ndarray, float]:
    """The commanded body rates clipped to +-max_rate per axis and the thrust clipped to
    [0, 1] times the maximum thrust (N)."""
    return np.clip(rates, -max_rate, max_rate), min(max(thrust, 0.0), 1.0) * max_thrust_n


# ---------------------------------------------------------------- the air
def jet_factor(
    mean: np.ndarray, source: np.ndarray, dia: float, p: np.ndarray, on_axis: bool
) -> float:
    """U(x, r) / U_0 of a round turbulent jet along ``mean`` from the outlet ``source`` of
    diameter D (wind.py): with x the distance along the axis and r from it,

        U(x, r) / U_0 = min(B D / x, 1) exp(-ln 2 r^2 / r_1/2^2),  r_1/2 = max(D / 2, S x)

    B = 5.8, S = 0.094 (Hussein, Capp & George 1994; Pope, *Turbulent Flows*, Table 5.1);
    with ``on_axis`` the centreline min(B D / x, 1) alone; 0 behind the outlet or without a
    mean."""
    speed = float(np.linalg.norm(mean))
    if speed <= 0.0:
        return 0.0
    d = p - source
    x = float(d @ mean) / speed
    if x <= 0.0:
        return 0.0
    core = min(P.JET_DECAY_B * dia / x, 1.0)
    if on_axis:
        return core
    r2 = max(float(d @ d) - x * x, 0.0)
    r_half = max(0.5 * dia, P.JET_SPREAD_S * x)
    return core * math.exp(-math.log(2.0) * r2 / r_half**2)


@dataclass(frozen=True)
class WindParams:
    """The wind's constants (:class:`.wind.Wind`'s ``params``, the kernels' W_* array) by
    name."""

    mean_m_s: np.ndarray
    sigma_m_s: np.ndarray  # the turbulence's standard deviation per axis
    time_s: float
    n_modes: int
    jet: bool  # a fan's round jet (else uniform)
    ref_profile: float  # U_c(x_ref) / U_0 at the reference point
    source_m: np.ndarray  # the fan's outlet centre
    dia_m: float  # the fan's outlet diameter

    @classmethod
    def of(cls, c: np.ndarray) -> WindParams:
        return cls(
            mean_m_s=c[P.W_MEAN : P.W_MEAN + 3].copy(),
            sigma_m_s=c[P.W_SIGMA : P.W_SIGMA + 3].copy(),
            time_s=float(c[P.W_TIME]),
            n_modes=int(c[P.W_NMODES]),
            jet=c[P.W_JET] != 0.0,
            ref_profile=float(c[P.W_REF]),
            source_m=c[P.W_SOURCE : P.W_SOURCE + 3].copy(),
            dia_m=float(c[P.W_DIA]),
        )


def turbulence_at(w: WindParams, modes: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The turbulence u (m/s ENU) at p (m) at the time t: a frozen field of N random Fourier
    modes (Kraichnan, Phys. Fluids 13, 1970) carried by the mean wind W (Taylor's hypothesis),

        u(p, t) = sigma (x) sum_n [c_n cos(k_n . (p - W t)) + s_n sin(k_n . (p - W t))]

    k_n the modes' wavenumbers (rad/m, drawn from the von Karman spectrum), c_n, s_n their
    amplitudes across k_n (unit variance per axis over space), sigma the standard deviations
    per axis (wind.py, MIL-F-8785C)."""
    m = modes[: max(min(w.n_modes, len(modes)), 0)]  # never past the modes given
    k, c, s = m[:, P.M_K : P.M_K + 3], m[:, P.M_C : P.M_C + 3], m[:, P.M_S : P.M_S + 3]
    phase = k @ (p - w.mean_m_s * w.time_s)
    return w.sigma_m_s * (np.cos(phase) @ c + np.sin(phase) @ s)


def wind_at(w: WindParams, modes: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The wind (m/s ENU) at p now: W + u(p, t) (:func:`turbulence_at`), for the fan jet times
    its profile relative to the reference point, U(p) / U_c(x_ref) (:func:`jet_factor`)."""
    air = w.mean_m_s + turbulence_at(w, modes, p)
    if not w.jet:
        return air
    return jet_factor(w.mean_m_s, w.source_m, w.dia_m, p, False) / w.ref_profile * air


def rotor_wash_at(x: np.ndarray, a: Airframe, wind: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The air the vehicle's rotors push (m/s ENU) at p (m), the vehicle's state x (X_*) in
    the wind w where it is. Momentum theory (Leishman, *Principles of Helicopter
    Aerodynamics* §2.14): the hover induced velocity and, in edgewise flight at the in-plane
    airspeed V = |v_a - (v_a . z_B) z_B|, Glauert's

        v_h^2 = T / (2 rho A),   v_i^2 = (sqrt(V^4 + 4 v_h^4) - V^2) / 2

    (T thrust N, A the discs' area m^2, as one disc). The developed slipstream moves at 2 v_i
    along -z_B through half the disc's area (mass flow kept at twice the speed), a diameter
    D = sqrt(4 A / pi) / sqrt(2), and beyond spreads and decays as a round jet
    (:func:`jet_factor`) from the vehicle along its path relative to the vehicle,
    -2 v_i z_B - v_a:

        wash(p) = -2 v_i f(p) z_B

    Nothing without thrust or discs, nor behind the jet's start (docs/air.md)."""
    thrust_n = float(x[P.X_THRUST])
    if a.disc_area_m2 <= 0.0 or thrust_n <= 0.0:
        return np.zeros(3)
    z_B = thrust_axis(x[P.X_Q : P.X_Q + 4])
    v_air = x[P.X_V : P.X_V + 3] - wind
    edgewise = v_air - float(v_air @ z_B) * z_B
    V2 = float(edgewise @ edgewise)
    vh2 = thrust_n / (2.0 * RHO * a.disc_area_m2)
    v_i = math.sqrt(0.5 * (math.sqrt(V2**2 + 4.0 * vh2**2) - V2))
    slipstream = -2.0 * v_i * z_B
    dia = math.sqrt(4.0 * a.disc_area_m2 / math.pi) / math.sqrt(2.0)
    f = jet_factor(slipstream - v_air, x[P.X_P : P.X_P + 3], dia, p, False)
    return f * slipstream


# ---------------------------------------------------------------- the integrator
def closest_approach(r0: np.ndarray, r1: np.ndarray) -> tuple:
    """The closest approach of a relative position moving linearly from r0 to r1 over a step:
    s = clip(-r0 . d / |d|^2, 0, 1), d = r1 - r0; (|r0 + s d|, s, r0 + s d, r0 . d, r1 . d)."""
    d = r1 - r0
    s = min(max(-float(r0 @ d) / float(d @ d), 0.0), 1.0) if float(d @ d) > 0.0 else 0.0
    c = r0 + s * d
    return float(np.linalg.norm(c)), s, c, float(r0 @ d), float(r1 @ d)


def sphere_image(
    R_WC: np.ndarray, c: np.ndarray, t: np.ndarray, diameter_m: float, f_px: float, c_px: np.ndarray
) -> tuple[np.ndarray | None, float]:
    """A sphere of ``diameter_m`` at t seen by a pinhole camera at c: its centre's pixel
    (None behind the camera) and its image radius f R / sqrt(|p|^2 - R^2) (px), p = R_WC^T
    (t - c) (the tangent cone's half-angle)."""
    p_C = R_WC.T @ (t - c)
    R = diameter_m / 2.0
    return pixel_of(p_C, f_px, c_px), f_px * R / math.sqrt(max(float(p_C @ p_C) - R * R, 1e-12))


def physics_steps(
    k0: int, n: int, buf: np.ndarray, track: np.ndarray, modes: np.ndarray
) -> tuple[int, np.ndarray]:
    """Steps k0 .. k0 + n of the sortie in ``buf`` (S_* layout), at t = k dt each:

    1. the command arrives when due (:func:`vehicle_command`);
    2. the air at the start of the step: the wind where the vehicle is; for a light target
       (tethered, balloon) the wind where it is plus the vehicle's rotor wash there;
    3. the vehicle steps (:func:`vehicle_step`), the target moves to t + dt
       (:func:`.target_reference.target_state`; a kinematic target in still air, seeing the
       vehicle where it is after its step);
    4. the closest approach inside the step (:func:`closest_approach`): before the pass the
       miss so far with its time, the vehicle's speed, the relative position and velocity;
       the pass is when, within 3 m, the range was closing at the step's start (or at the
       previous step's end) and opens at its end: HIT if the miss is within the hit radius,
       else MISS; after it the lowest altitude;
    5. the outcome that ends the sortie: diverged (not finite, or faster than 60 m/s), or
       crashed (at or below the ground).

    Returns (steps taken, the new buffer)."""
    buf = buf.copy()
    vx = buf[P.S_VX : P.S_VX + P.X_SIZE]
    airframe = Airframe.of(buf[P.S_LAG : P.S_LAG + P.L_SIZE])
    tc, tx = buf[P.S_TC : P.S_TC + TK.T_SIZE], buf[P.S_TX : P.S_TX + TK.TX_SIZE]
    wc = buf[P.S_WC : P.S_WC + P.W_SIZE]
    cs = buf[P.S_CS : P.S_CS + P.C_SIZE]
    cmd = buf[P.S_CMD : P.S_CMD + 7]  # due step, rates (3), thrust, rate limit, max thrust
    dt, kind = buf[P.S_DT], TK.MOTIONS[int(buf[P.S_KIND])]
    light = kind in ("tethered", "balloon")
    for k in range(k0, k0 + n):
        t = k * dt
        wc[P.W_TIME] = t
        wind = WindParams.of(wc)
        if 0.0 <= cmd[0] <= k:
            rates, thrust = vehicle_command(cmd[1:4], cmd[4], cmd[5], cmd[6])
            vx[P.X_CMD_W : P.X_CMD_W + 3], vx[P.X_CMD_THRUST] = rates, thrust
            cmd[0] = -1.0
        w_vehicle = wind_at(wind, modes, vx[0:3])
        air = np.zeros(3)
        if light:
            air = wind_at(wind, modes, tx[0:3]) + rotor_wash_at(vx, airframe, w_vehicle, tx[0:3])
        vx[:] = vehicle_step(vx, airframe, dt, w_vehicle)
        p, v = vx[P.X_P : P.X_P + 3].copy(), vx[P.X_V : P.X_V + 3].copy()
        tx[:] = target_state(kind, tc, track, tx, t + dt, dt, air, p)
        r0, r1 = cs[P.C_REL : P.C_REL + 3].copy(), tx[0:3] - p
        dist, s, closest, r0d, r1d = closest_approach(r0, r1)
        cs[P.C_REL : P.C_REL + 3] = r1
        passed = cs[P.C_PASS] != 0.0
        if not passed and dist < cs[P.C_MISS]:
            cs[P.C_MISS], cs[P.C_TIME], cs[P.C_SPEED] = dist, t + s * dt, np.linalg.norm(v)
            cs[P.C_CLOSE_REL : P.C_CLOSE_REL + 3] = closest
            cs[P.C_CLOSE_VEL : P.C_CLOSE_VEL + 3] = v
        closing = r0d < 0.0 or cs[P.C_ENDED_CLOSING] != 0.0
        cs[P.C_ENDED_CLOSING] = float(r1d < 0.0)
        if passed:
            cs[P.C_MIN_ALT] = min(cs[P.C_MIN_ALT], p[2])
        elif dist < P.PASS_RADIUS_M and closing and r1d > 0.0:
            hit = cs[P.C_MISS] <= cs[P.C_HIT_R]
            cs[P.C_PASS] = P.OUTCOME_HIT if hit else P.OUTCOME_MISS
            cs[P.C_PASS_TIME], cs[P.C_MIN_ALT] = t + dt, p[2]
        outcome = P.OUTCOME_NONE
        if (
            not np.isfinite(vx[: P.X_W + 3]).all()
            or not np.isfinite(r1).all()
            or v @ v > P.DIVERGED_SPEED_M_S**2
        ):
            outcome = P.OUTCOME_DIVERGED
        elif p[2] <= 0.0:
            outcome = P.OUTCOME_CRASHED
        if outcome != P.OUTCOME_NONE:
            cs[P.C_OUTCOME] = outcome
            return k - k0 + 1, buf
    return n, buf
