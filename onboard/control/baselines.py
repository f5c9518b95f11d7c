"""The baselines the paper compares against (DESIGN §5): pure pursuit guidance (PG) and
image-based visual servoing (IBVS), each with a velocity loop like PX4's."""

from __future__ import annotations

import math

import numpy as np

from ..gains import Gains
from .guidance_io import GuidanceInput, GuidanceOutput, _hover_start
from .los import direction_angles, saturate_norm


def track_velocity_direction(
    direction: np.ndarray,
    v: np.ndarray,
    speed: float,
    gains: Gains,
    speed_cap_m_s: float = math.inf,
) -> np.ndarray:
    """The baselines' velocity loop: a_d = k_v (v_d - v), saturated to a_max, with
    |v_d| = |v| + k_a / k_v (capped at v_max and at ``speed_cap_m_s``, the approach's limit
    near the ground) so that, once aligned, the tangential acceleration is k_a as in the
    proposed law's speed ramp (eq. 14).

    The proposed law's eq. 17 divides by the tick (a gain of 1/dt = 100 1/s). That suits PNG,
    whose v_d is v turned by K dq, but a law that asks for whole heading corrections turns it
    into a saturated limit cycle through the attitude lag; no fair baseline flies like that.
    """
    v_d = min(speed + gains.k_a / gains.k_v, gains.v_max, speed_cap_m_s) * direction
    return saturate_norm(gains.k_v * (v_d - v), gains.a_max)


def pursuit_law(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    """PG baseline: desired velocity along the LOS (DESIGN §5)."""
    v = inp.velocity_enu_m_s
    speed = math.sqrt(float(v @ v))
    if speed < gains.v_min:
        return _hover_start(inp, gains)
    sigma_y, sigma_z = direction_angles(v / speed)
    a_d = track_velocity_direction(inp.los_enu, v, speed, gains, inp.speed_cap_m_s)
    return GuidanceOutput(a_d, sigma_y, sigma_z, False)


def ibvs_law(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    """IBVS baseline, the authors' earlier approach (DESIGN §5): fly along the optical axis
    and drive the image error to zero with the translational part of L_s (eq. 4).

    With camera-frame velocity v_c = v_z ((1 + k) e_x, (1 + k) e_y, 1), eq. 4 gives
    de/dt = -k e v_z / Z: the image error decays as the range closes. Velocity loop as PG.
    """
    v = inp.velocity_enu_m_s
    speed = math.sqrt(float(v @ v))
    if speed < gains.v_min:
        return _hover_start(inp, gains)
    sigma_y, sigma_z = direction_angles(v / speed)
    g = 1.0 + gains.k_ibvs
    d = inp.R_WC @ np.array([g * inp.e_norm[0], g * inp.e_norm[1], 1.0])
    a_d = track_velocity_direction(d / math.sqrt(float(d @ d)), v, speed, gains, inp.speed_cap_m_s)
    return GuidanceOutput(a_d, sigma_y, sigma_z, False)
