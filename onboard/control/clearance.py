"""Ground clearance near a low target (not in the paper; docs/core.md, "Low targets: the
descent limit and the recovery").

A target a metre or two above the ground is met in a dive: PNG turns the velocity onto the
collision course, and from a level start its flight path ends steeper than the line of sight
was (sigma - sigma_0 = K (q - q_0)). At the speed ramp's cruise the vehicle passes such a
target descending at several m/s, with less height left below it than it needs to stop. Two
parts keep it off the ground, both from what the vehicle believes (its airframe, its own
altitude above home, the DKF's line of sight and range), never from a scenario's truth:

- **the approach's speed** along the track is capped so that the descent rate at the target
  leaves room to stop above ``h_clear``: v_cap = v_down / sin(gamma), gamma the descent angle
  (the steeper of the velocity's and the line of sight's), v_down the descent rate from which
  the upward capability a_up stops within the target's height above ``h_clear`` after the
  response lag ``t_up_lag``. The cap lowers the speed ramp's reference (eq. 14), which PN
  leaves free: it changes how fast the vehicle flies along its path, not where the path goes
  (capping the vertical velocity instead bends the vehicle off its collision course). Far away
  the cap is raised by what the ramp can shed on the way (sqrt(v^2 + 2 a_dec R)), so the
  vehicle slows in time without slowing early.
- **the recovery**: whenever the descent rate exceeds what a_up can stop above ``h_clear``
  from the vehicle's own height (the same braking curve), the vertical command is a_up. An
  approach that met its cap reaches that curve only below the target, after the pass; the
  brake after the pass nulls the descent with up to a_up too.

a_up is the believed airframe's upward capability, ``k_up`` (TW - 1) g with the thrust-to-weight
ratio TW = 1 / hover thrust (PRG_HOVER_THR), not the guidance's ``a_max``: the recovery is not a
guidance manoeuvre, and the airframe can give far more upward than the guidance's cap.
``k_up`` = 0 switches both parts off.

The target's height is the vehicle's altitude plus the range times the line of sight's vertical
component, with the range taken at the end of its interval (the DKF's inverse depth
``RANGE_SIGMAS`` sigma either way) that puts the target lowest: a poorly known range is taken
as a low target. Pure: floats in, floats out.
"""

from __future__ import annotations

import math

import numpy as np

from ..datatypes import GRAVITY_M_S2
from ..gains import Gains

RANGE_SIGMAS = 2.0  # the range interval's half-width, in sigma of the DKF's inverse depth
# the cap aims below the recovery's braking curve by this factor: the speed ramp tracks its
# reference with a lag, and the recovery must not act before the pass
CAP_FRACTION = 0.8
SIN_DESCENT_MIN = 0.02  # a level path has no descent to limit (the cap is then v_max)
CAP_FLOOR_M_S = 1.0  # the cap never asks for less (below v_min the law would fly the LOS)


def upward_accel_m_s2(hover_thrust: float, k_up: float) -> float:
    """a_up = k_up (TW - 1) g (m/s^2), TW = 1 / ``hover_thrust`` (normalised, in (0, 1]):
    the part ``k_up`` of the believed airframe's upward acceleration at full thrust."""
    if not 0.0 < hover_thrust <= 1.0:
        raise ValueError(f"hover thrust {hover_thrust} is not in (0, 1]")
    return k_up * (1.0 / hover_thrust - 1.0) * GRAVITY_M_S2


def stoppable_descent_m_s(height_m: float, a_up_m_s2: float, lag_s: float) -> float:
    """The fastest descent (m/s, >= 0) that stops within ``height_m``: held for ``lag_s``
    before the deceleration ``a_up_m_s2`` acts, v lag + v^2 / (2 a_up) = h, so
    v = sqrt((a_up lag)^2 + 2 a_up h) - a_up lag; 0 at or below no height."""
    if not height_m > 0.0 or not a_up_m_s2 > 0.0:
        return 0.0
    al = a_up_m_s2 * lag_s
    return math.sqrt(al * al + 2.0 * a_up_m_s2 * height_m) - al


def range_interval_m(
    range_m: float,
    e_norm: tuple[float, float],
    inv_depth_var: float,
    sigmas: float = RANGE_SIGMAS,
) -> tuple[float, float]:
    """(low, high) range along the LOS (m) with the DKF's inverse depth rho = sqrt(1 + |e_n|^2)
    / range moved ``sigmas`` sigma up and down (variance ``inv_depth_var``, 1/m^2); the high
    end is inf when rho is within that of zero."""
    if not (math.isfinite(range_m) and range_m > 0.0):
        return 0.0, math.inf
    rho = math.sqrt(1.0 + e_norm[0] ** 2 + e_norm[1] ** 2) / range_m
    d = sigmas * math.sqrt(max(inv_depth_var, 0.0)) if math.isfinite(inv_depth_var) else rho
    low = range_m * rho / (rho + d)
    high = range_m * rho / (rho - d) if rho > d else math.inf
    return low, high


def target_height_low_m(
    altitude_m: float, los_up: float, range_low_m: float, range_high_m: float
) -> float:
    """The lowest height of the target (m above home) the range interval allows: the
    vehicle's ``altitude_m`` plus the range times ``los_up`` (the unit LOS's vertical
    component), the range at the end of the interval that puts the target lowest (-inf when
    that end is unbounded)."""
    rng = range_high_m if los_up < 0.0 else range_low_m
    return altitude_m + rng * los_up if math.isfinite(rng) else -math.inf


def held_height_low_m(prev_low_m: float, dt_s: float, now_low_m: float, sink_m_s: float) -> float:
    """The target's lowest height held over the track: the previous bound lowered by the
    fastest sink the target is allowed (``sink_m_s`` over ``dt_s``), raised to this tick's
    bound if that is higher. The DKF's range is best in the middle of an approach; close in,
    with the blob clipped or filling the frame, its interval widens again, and a bound learnt
    earlier stays valid for a target that cannot sink faster."""
    return max(prev_low_m - sink_m_s * max(dt_s, 0.0), now_low_m)


def approach_speed_cap_m_s(
    target_low_m: float,
    los_up: float,
    velocity_enu_m_s: tuple[float, float, float],
    range_low_m: float,
    a_up_m_s2: float,
    gains: Gains,
) -> float:
    """The speed ramp's reference (m/s, at most ``v_max``) that leaves room to stop above
    ``h_clear`` after passing a target no lower than ``target_low_m`` (module docstring):
    ``los_up`` the unit LOS's vertical component, the velocity, the range's low end (m)."""
    v_max = gains.v_max
    v0, v1, v2 = (float(c) for c in velocity_enu_m_s)
    speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    sin_descent = max(-los_up, -v2 / speed if speed > 0.0 else 0.0)
    if sin_descent < SIN_DESCENT_MIN:
        return v_max
    v_down = CAP_FRACTION * stoppable_descent_m_s(
        target_low_m - gains.h_clear, a_up_m_s2, gains.t_up_lag
    )
    v_at = v_down / sin_descent
    # what the ramp can still shed on the way (half its k_a: it follows its reference late)
    shed = gains.k_a * max(range_low_m, 0.0)
    return min(max(math.sqrt(v_at * v_at + shed), CAP_FLOOR_M_S), v_max)


def clearance_guard_accel(
    accel_enu_m_s2: np.ndarray,
    altitude_m: float,
    vel_up_m_s: float,
    a_up_m_s2: float,
    gains: Gains,
) -> np.ndarray:
    """The recovery (module docstring): ``accel_enu_m_s2`` (m/s^2, ENU) with its vertical part
    raised to a_up while the descent is faster than :func:`stoppable_descent_m_s` of the
    height above ``h_clear`` (with ``t_up_lag``); otherwise the same array, unchanged."""
    v_ok = stoppable_descent_m_s(altitude_m - gains.h_clear, a_up_m_s2, gains.t_up_lag)
    if a_up_m_s2 <= 0.0 or not vel_up_m_s < -v_ok or not float(accel_enu_m_s2[2]) < a_up_m_s2:
        return accel_enu_m_s2
    return np.array((float(accel_enu_m_s2[0]), float(accel_enu_m_s2[1]), a_up_m_s2))


def track_speed_cap_m_s(
    prev_low_m: float,
    dt_s: float,
    altitude_m: float,
    los_enu: tuple[float, float, float],
    velocity_enu_m_s: tuple[float, float, float],
    e_norm: tuple[float, float],
    depth: tuple[float, object, np.ndarray] | None,
    a_up_m_s2: float,
    gains: Gains,
) -> tuple[float, float]:
    """One tick of the approach's limit from the DKF's ``depth`` (its ``depth_velocity()``:
    range along the LOS, target velocity, covariance with the inverse depth's variance at
    [2, 2]; None without one: the range unknown): (the speed cap m/s, the target's lowest
    height held, :func:`held_height_low_m` from ``prev_low_m``, -inf at a track's start);
    no cap (inf) when ``a_up_m_s2`` is 0 (switched off)."""
    if a_up_m_s2 <= 0.0:
        return math.inf, prev_low_m
    if depth is None:
        low, high = 0.0, math.inf
    else:
        low, high = range_interval_m(depth[0], e_norm, float(depth[2][2, 2]))
    los_up = float(los_enu[2])
    now = target_height_low_m(altitude_m, los_up, low, high)
    held = held_height_low_m(prev_low_m, dt_s, now, gains.v_tgt_sink)
    cap = approach_speed_cap_m_s(held, los_up, velocity_enu_m_s, low, a_up_m_s2, gains)
    return cap, held


def brake_accel(
    velocity_enu_m_s: np.ndarray, gains: Gains, a_up_m_s2: float | None = None
) -> np.ndarray:
    """Brake and hold (after the pass, on an abort, with the target lost): the vertical
    velocity nulled first (``k_brake_z``, down at most ``a_max``, up at most ``a_up_m_s2``,
    the believed airframe's upward capability, :func:`upward_accel_m_s2`;
    ``a_max`` when None: a vehicle diving through a low target must not reach the ground),
    the horizontal with ``k_brake`` in what is left of ``a_max`` (m/s^2, ENU)."""
    v0, v1, v2 = (float(c) for c in velocity_enu_m_s)
    a_max = gains.a_max
    a_up = a_max if a_up_m_s2 is None else max(a_up_m_s2, a_max)
    az = min(max(-gains.k_brake_z * v2, -a_max), a_up)
    room = math.sqrt(max(a_max * a_max - az * az, 0.0))
    ax, ay = -gains.k_brake * v0, -gains.k_brake * v1
    n = math.hypot(ax, ay)
    if n > room:
        ax, ay = ax * room / n, ay * room / n
    return np.array((ax, ay, az))
