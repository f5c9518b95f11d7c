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


# ---------------------------------------------------------------- the targets
def balloon_force(
    v_rel: np.ndarray,
    phase_rad: float,
    drag_k: float,
    net_lift_n: float,
    c_l: float,
    area_m2: float,
) -> np.ndarray:
    """The air's force (N) on a light target with the air moving at v_r (m/s) relative to it:

        F = k |v_r| v_r + L e_z + C_L' (rho / 2) |v_r|^2 A sin(phase) s^

    quadratic drag (k = 0.5 rho C_d A, kg/m), the net lift L (N), and the buffet of its shed
    vortices: horizontal, across the relative wind, s^ = (v_r x e_z) / |v_r x e_z| ((1, 0, 0)
    when the air moves vertically only), none without a wake (C_L' = 0 or |v_r| <= 1e-6 m/s)
    (docs/air.md; Achenbach 1974, Howe, Lauchle & Wang 2001)."""
    speed = float(np.linalg.norm(v_rel))
    force = drag_k * speed * v_rel + net_lift_n * E_UP
    if c_l > 0.0 and speed > 1e-6:
        across = np.cross(v_rel, E_UP)
        h = float(np.linalg.norm(across))
        side = across / h if h > 1e-9 else np.array([1.0, 0.0, 0.0])
        force = force + c_l * 0.5 * RHO * speed**2 * area_m2 * math.sin(phase_rad) * side
    return force


def target_state(
    kind: str,
    c: np.ndarray,
    track: np.ndarray,
    x: np.ndarray,
    t: float,
    dt: float,
    air: np.ndarray,
) -> np.ndarray:
    """The target's state (position m, velocity m/s, buffet phase rad; the TX_* array) at
    time t (s), a step of dt after ``x``, for each motion (targets.py), ``air`` the wind where
    it is (m/s; a light target's):

    - static: where it was put;
    - cv: p = p0 + v0 t (velocity as given);  ca: p = p0 + v0 t + a t^2 / 2, v = v0 + a t;
    - sinusoid: p = p0 + v0 t + A sin(w t), v = v0 + A w cos(w t);
    - circle: p = c + r (cos w t, sin w t, 0) + v0 t, v = r w (-sin w t, cos w t, 0) + v0;
    - takeoff: p = p0 + v0 max(t - t_start, 0), v = v0 after t_start, 0 before;
    - escape: v <- v + a dt, scaled down to the top speed; p <- p + v dt;
    - tethered, balloon: v <- v + F / m dt (:func:`balloon_force` with v_r = air - v, m with
      the added air mass), p <- p + v dt; the buffet's phase advances by 2 pi St |v_r| / D dt
      (mod 2 pi; Strouhal shedding); a tethered one is held by its rope: beyond the rope's
      length from the anchor it is put back onto that sphere and its outward radial velocity
      dropped;
    - track: linear between the recorded samples, continued at the last velocity.

    Then the ground: a moving target below z = 0 is put on it and its vertical velocity is
    no longer downward (its horizontal motion goes on)."""
    p0, v0, a0 = c[P.T_P0 : P.T_P0 + 3], c[P.T_V0 : P.T_V0 + 3], c[P.T_A0 : P.T_A0 + 3]
    p, v, phase = x[0:3].copy(), x[3:6].copy(), float(x[6])
    if kind == "static":
        return x.copy()
    if kind == "cv":
        p = p0 + v0 * t
    elif kind == "ca":
        p, v = p0 + v0 * t + 0.5 * a0 * t * t, v0 + a0 * t
    elif kind == "sinusoid":
        amplitude, w = c[P.T_AMP : P.T_AMP + 3], c[P.T_SIN_W]
        p, v = p0 + v0 * t + amplitude * math.sin(w * t), v0 + amplitude * w * math.cos(w * t)
    elif kind == "circle":
        centre, r, w = c[P.T_CENTER : P.T_CENTER + 3], c[P.T_RADIUS], c[P.T_CIRCLE_W]
        ring = np.array([math.cos(w * t), math.sin(w * t), 0.0])
        p = centre + r * ring + v0 * t
        v = r * w * np.array([-ring[1], ring[0], 0.0]) + v0
    elif kind == "takeoff":
        start_s = c[P.T_START]
        p = p0 + v0 * max(t - start_s, 0.0)
        v = v0.copy() if t > start_s else np.zeros(3)
    elif kind == "escape":
        top_speed = c[P.T_MAX_SPEED]
        v = v + a0 * dt
        speed = float(np.linalg.norm(v))
        if speed > top_speed:
            v = v * (top_speed / speed)
        p = p + v * dt
    elif kind in ("tethered", "balloon"):
        drag_k, net_lift_n, mass_kg = c[P.T_DRAG_K], c[P.T_LIFT], c[P.T_MASS]
        c_l, strouhal, diameter_m, area_m2 = c[P.T_CL], c[P.T_STROUHAL], c[P.T_DIA], c[P.T_AREA]
        v_rel = air - v
        force = balloon_force(v_rel, phase, drag_k, net_lift_n, c_l, area_m2)
        speed = float(np.linalg.norm(v_rel))
        if c_l > 0.0 and speed > 1e-6:
            shedding_hz = strouhal * speed / diameter_m
            phase = math.fmod(phase + 2.0 * math.pi * shedding_hz * dt, 2.0 * math.pi)
        v = v + force / mass_kg * dt
        p = p + v * dt
        anchor, rope_m = c[P.T_ANCHOR : P.T_ANCHOR + 3], c[P.T_ROPE]
        d = p - anchor
        if kind == "tethered" and np.linalg.norm(d) > rope_m:
            u = d / np.linalg.norm(d)
            p = anchor + rope_m * u
            v = v - max(float(v @ u), 0.0) * u
    elif kind == "track":
        times, points = track[:, 0], track[:, 1:4]
        i = min(max(int(np.searchsorted(times, t, side="right")) - 1, 0), len(track) - 2)
        v = (points[i + 1] - points[i]) / (times[i + 1] - times[i])
        p = points[i] + v * (t - times[i])
    if p[2] < 0.0:
        p[2], v[2] = 0.0, max(v[2], 0.0)
    return np.concatenate([p, v, [phase]])


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
       (:func:`target_state`; a kinematic target in still air);
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
    tc, tx = buf[P.S_TC : P.S_TC + P.T_SIZE], buf[P.S_TX : P.S_TX + P.TX_SIZE]
    wc = buf[P.S_WC : P.S_WC + P.W_SIZE]
    cs = buf[P.S_CS : P.S_CS + P.C_SIZE]
    cmd = buf[P.S_CMD : P.S_CMD + 7]  # due step, rates (3), thrust, rate limit, max thrust
    dt, kind = buf[P.S_DT], P.MOTIONS[int(buf[P.S_KIND])]
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
        tx[:] = target_state(kind, tc, track, tx, t + dt, dt, air)
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
