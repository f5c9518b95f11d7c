"""Augmented proportional navigation (APN): the proposed law (:func:`.png.png_floats`) plus
N/2 times the target's acceleration normal to the line of sight, with a command limit from
the airframe the vehicle believes in place of the fixed ``a_max`` (docs/agility.md).

PN with navigation constant N nulls the LOS rate of a target that does not accelerate; a
target accelerating at a_T normal to the LOS leaves PN a miss that grows with a_T t_go^2, and
PN's own command rises to N/(N-2) a_T near the end. APN adds N/2 a_T,perp, the term that makes
the commanded acceleration the zero-effort-miss solution for a constant-acceleration target
(Zarchan, Tactical and Strategic Missile Guidance, ch. 8): a_APN = N V_c q' + N/2 a_T,perp.
Here N is the mean of the velocity-angle gains K_y and K_z (eq. 8), and a_T is the part of
the IMM's estimate of the target's acceleration (onboard/estimation/imm.py) normal to the
target's velocity (:func:`manoeuvre_accel_m_s2`). N/2 a_T is the zero-effort miss of an
acceleration fixed in direction over the time to go; a target in a coordinated turn turns its
acceleration with its velocity, at omega = (v x a)_z / |v_h|^2 (the IMM's CT model), and over
t_go = 1 s at 1-1.5 rad/s that prediction is off by R (omega t - sin omega t), 0.8-1.7 m,
several hit radii. With the gain ``t_turn`` > 0 the law flies the turn's own zero-effort miss
instead (:func:`turn_prediction_accel_m_s2`): a_APN = N V_c q' + N / t^2 (d(t) - v t)_perp,
d(t) - v t the target's displacement beyond its velocity's over the horizon t = min(t_go,
t_turn). It is off by default: flown with the IMM's estimate, which holds about half of a
turn's acceleration, it hits no more turning targets than the fixed prediction (handed the
true acceleration and turn rate it does, from 7.5 m/s^2 on; docs/agility.md).

Within ``r_end`` of the target the speed ramp's reference is at most ``v_end`` over the
target's speed (:func:`endgame_speed_cap_m_s`): a hovering target is closed on at ``v_end``
instead of 9-11 m/s, which leaves the vehicle the time to answer a dart from 3-5 m.

The command limit is the lateral acceleration the airframe can hold level: thrust-to-weight
TW = 1 / hover thrust (PRG_HOVER_THR) gives sqrt((TW g)^2 - (g + a_z)^2) with ``a_z_margin``
kept for the vertical, capped by the tilt limit, g tan(tilt_max). The FOV guard
(:func:`.png.fov_guard_floats`) then limits the pitch-down as for PNG.
"""

from __future__ import annotations

import math

import numpy as np

from ..datatypes import GRAVITY_M_S2
from ..estimation.imm import MIN_TURN_SPEED_M_S, MotionEstimate, turn_displacement
from ..gains import GainIndex, Gains
from .guidance_io import GuidanceInput, GuidanceOutput
from .los import _f3, saturate3
from .png import fov_guard_floats, png_floats


def available_lateral_accel_m_s2(
    hover_thrust: float, tilt_max_deg: float, a_z_margin: float
) -> float:
    """The lateral acceleration (m/s^2) an airframe hovering at ``hover_thrust`` (normalised,
    = 1 / thrust-to-weight) can hold while keeping ``a_z_margin`` (m/s^2) of vertical
    acceleration, and no more than its tilt limit allows level: min(sqrt((TW g)^2 - (g +
    a_z)^2), g tan(tilt_max)); 0 when the thrust cannot even hold the margin."""
    if not 0.0 < hover_thrust <= 1.0:
        raise ValueError(f"hover thrust {hover_thrust} is not in (0, 1]")
    thrust = GRAVITY_M_S2 / hover_thrust
    vertical = GRAVITY_M_S2 + a_z_margin
    by_thrust = math.sqrt(max(thrust * thrust - vertical * vertical, 0.0))
    return min(by_thrust, GRAVITY_M_S2 * math.tan(math.radians(tilt_max_deg)))


def time_to_go_s(
    range_m: float | None,
    los_enu: tuple[float, float, float],
    velocity_enu_m_s: np.ndarray,
    motion: MotionEstimate | None,
) -> float:
    """R / V_c (s): the DKF's range over the closing speed, the vehicle's velocity less the
    target's (the IMM's; zero without it) along the unit LOS; nan without a range or when
    not closing."""
    if range_m is None or not math.isfinite(range_m):
        return math.nan
    n0, n1, n2 = los_enu
    v0, v1, v2 = (float(c) for c in velocity_enu_m_s)
    if motion is not None:
        t0, t1, t2 = motion.velocity_enu_m_s
        v0, v1, v2 = v0 - t0, v1 - t1, v2 - t2
    closing = v0 * n0 + v1 * n1 + v2 * n2
    return range_m / closing if closing > 0.0 else math.nan


def manoeuvre_accel_m_s2(
    motion: MotionEstimate | None, z_off: float, z_full: float
) -> tuple[float, float, float] | None:
    """The IMM's acceleration (m/s^2 ENU) normal to its target velocity, as far as it stands
    out of its own noise: scaled by w = clip((z - z_off) / (z_full - z_off), 0, 1), z = |a| /
    sqrt(tr P_a / 3) its size in standard deviations. An acceleration within its noise is no
    manoeuvre: APN then flies PN and does not chase the estimate's noise with its larger
    limit. The part along the velocity changes the target's speed, which its speed range
    bounds: a jink ends within a few tenths of a second, before the estimate has seen it, so
    flown it aims where the target no longer goes; a turn's normal part changes no speed and
    lasts. Under MIN_TURN_SPEED_M_S all of it is speed change. None without an estimate."""
    if motion is None:
        return None
    a0, a1, a2 = motion.accel_enu_m_s2
    norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    sigma = math.sqrt(max(motion.accel_var_m2_s4, 0.0) / 3.0)
    z = norm / sigma if sigma > 0.0 else math.inf
    w = min(max((z - z_off) / (z_full - z_off), 0.0), 1.0) if z_full > z_off else float(z >= z_off)
    v0, v1, v2 = motion.velocity_enu_m_s
    speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if not speed > MIN_TURN_SPEED_M_S:
        return 0.0, 0.0, 0.0
    along = (a0 * v0 + a1 * v1 + a2 * v2) / (speed * speed)
    a0, a1, a2 = a0 - along * v0, a1 - along * v1, a2 - along * v2
    return a0 * w, a1 * w, a2 * w


def turn_prediction_accel_m_s2(
    target_accel_enu_m_s2: tuple[float, float, float],
    turn_rate_rad_s: float,
    time_to_go_s: float,
    horizon_max_s: float,
) -> tuple[float, float, float]:
    """The constant acceleration (m/s^2 ENU) that displaces the target over the horizon t =
    min(t_go, ``horizon_max_s``) as its acceleration a turning at ``turn_rate_rad_s`` (about
    +z) does: a_eq = 2 / t^2 (d(t) - v t), d(t) - v t = (B2(omega, t) a_h, a_z t^2 / 2) with
    B2 the turn's double integral (imm.turn_displacement). For a coordinated turn (a_h normal
    to v_h, omega = |a_h| / |v_h|) that is ((sin wt)/w - t) v + ((1 - cos wt)/w^2) a, so N/2
    a_eq,perp is the turn's zero-effort-miss term N / t^2 (d(t) - v t)_perp. It is a as omega
    -> 0 or t -> 0, and a without a time to go (nan) or a horizon (0)."""
    t = min(time_to_go_s, horizon_max_s)
    if not (t > 0.0 and turn_rate_rad_s != 0.0 and math.isfinite(turn_rate_rad_s)):
        return target_accel_enu_m_s2
    a0, a1, a2 = target_accel_enu_m_s2
    B = turn_displacement(turn_rate_rad_s, t) * (2.0 / (t * t))
    return (
        float(B[0, 0] * a0 + B[0, 1] * a1),
        float(B[1, 0] * a0 + B[1, 1] * a1),
        a2,
    )


MIN_TURN_ACCEL_M_S2 = 0.5  # a flown acceleration under this is no turn to match
MIN_TURN_RATE_RAD_S = 0.05  # nor a turn rate under this (a radius over 100 m at 5 m/s)


def turn_speed_cap_m_s(
    target_accel_enu_m_s2: tuple[float, float, float] | None,
    turn_rate_rad_s: float,
    accel_limit_m_s2: float,
    k: float,
) -> float:
    """k times the speed (m/s) at which the vehicle's tightest turn (radius v^2 / a_lim) is the
    target's (|a_T| / omega^2, a_T its flown acceleration turning at omega): k sqrt(a_lim
    |a_T|) / |omega|. A vehicle faster than that circles outside a target that turns inside
    it. inf when k is 0, without a turn (|a_T| under MIN_TURN_ACCEL_M_S2, |omega| under
    MIN_TURN_RATE_RAD_S, a target slower than MIN_TURN_SPEED_M_S) or without a limit."""
    w = abs(turn_rate_rad_s)
    if target_accel_enu_m_s2 is None or not (k > 0.0 and w >= MIN_TURN_RATE_RAD_S):
        return math.inf
    a = math.sqrt(sum(c * c for c in target_accel_enu_m_s2))
    if not (a >= MIN_TURN_ACCEL_M_S2 and a / w > MIN_TURN_SPEED_M_S and accel_limit_m_s2 > 0.0):
        return math.inf
    return k * math.sqrt(accel_limit_m_s2 * a) / w


def endgame_speed_cap_m_s(range_m: float, target_speed_m_s: float, gains: Gains) -> float:
    """The speed ramp's cap (m/s) near the target: within ``r_end`` (m) of it, ``v_end`` more
    than the target's speed (0 when unknown); inf when ``v_end`` is 0 (off), farther or with
    the range unknown (nan). A hovering target is closed on at ``v_end``, which leaves the
    vehicle the time to answer a late dart; one in flight, ``v_end`` faster than it flies."""
    if not (gains.v_end > 0.0 and range_m < gains.r_end):
        return math.inf
    return gains.v_end + (target_speed_m_s if math.isfinite(target_speed_m_s) else 0.0)


def apn_term(
    target_accel_enu_m_s2: tuple[float, float, float],
    los_enu: tuple[float, float, float],
    navigation_constant: float,
) -> tuple[float, float, float]:
    """N/2 a_T,perp (m/s^2 ENU): the target's acceleration without its part along the unit
    LOS n, times N/2."""
    a0, a1, a2 = target_accel_enu_m_s2
    n0, n1, n2 = los_enu
    along = a0 * n0 + a1 * n1 + a2 * n2
    k = 0.5 * navigation_constant
    return k * (a0 - along * n0), k * (a1 - along * n1), k * (a2 - along * n2)


def apn_law(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    """APN (module docstring): PNG with the airframe's limit ``inp.accel_limit_m_s2`` (the
    gains' a_max when it is not given), plus N/2 a_T,perp when the target's acceleration is
    known (turned at ``inp.target_turn_rate_rad_s`` over min(t_go, ``t_turn``),
    :func:`turn_prediction_accel_m_s2`), saturated to that limit, then the FOV guard; with
    ``k_turn_v`` > 0 the speed ramp's cap is at most :func:`turn_speed_cap_m_s`, and near the
    target :func:`endgame_speed_cap_m_s`."""
    base_lim = inp.accel_limit_m_s2 if math.isfinite(inp.accel_limit_m_s2) else gains.a_max
    lim = base_lim
    if inp.time_to_go_s < gains.t_end and math.isfinite(inp.endgame_accel_limit_m_s2):
        lim = max(lim, inp.endgame_accel_limit_m_s2)
    G = gains.packed.copy()
    G[GainIndex.a_max] = lim
    turn_cap = turn_speed_cap_m_s(
        inp.target_accel_enu_m_s2, inp.target_turn_rate_rad_s, base_lim, gains.k_turn_v
    )
    end_cap = endgame_speed_cap_m_s(inp.range_est_m, inp.target_speed_m_s, gains)
    G[GainIndex.v_max] = min(gains.v_max, inp.speed_cap_m_s, turn_cap, end_cap)
    vt = inp.target_vel_enu_m_s
    t0, t1, t2 = (math.nan,) * 3 if vt is None else _f3(vt)
    R = inp.R_WC
    top, bottom = inp.fov_edges_rad
    los = _f3(inp.los_enu)
    e0, e1, e2 = inp.disturbance_enu_m_s2
    a0, a1, a2, sigma_y, sigma_z, hovering = png_floats(
        inp.dt_s, *los, inp.los_elev_rad, inp.d_los_elev_rad, inp.d_los_azim_rad,
        *_f3(inp.velocity_enu_m_s), float(R[0, 2]), float(R[1, 2]), float(R[2, 2]), top, bottom,
        inp.range_m, vt is not None, t0, t1, t2, inp.target_vel_var_m2_s2, e0, e1, e2, G,
    )  # fmt: skip
    if hovering != 0.0:
        return GuidanceOutput(np.array((a0, a1, a2)), math.nan, math.nan, True)
    if inp.target_accel_enu_m_s2 is not None:
        k = 0.5 * (gains.K_y + gains.K_z)
        a_t = turn_prediction_accel_m_s2(
            inp.target_accel_enu_m_s2, inp.target_turn_rate_rad_s, inp.time_to_go_s, gains.t_turn
        )
        b0, b1, b2 = apn_term(a_t, los, k)
        a0, a1, a2 = saturate3(a0 + b0, a1 + b1, a2 + b2, lim)
        fov_margin = math.radians(gains.fov_margin)
        _, a0, a1, a2 = fov_guard_floats(
            a0, a1, a2, top, float(R[0, 2]), float(R[1, 2]), inp.los_elev_rad, fov_margin, lim
        )
    return GuidanceOutput(np.array((a0, a1, a2)), sigma_y, sigma_z, False)
