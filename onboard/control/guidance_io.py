"""What a guidance law reads and returns at one control tick, and the start from hover that
every law shares (DESIGN §3.4)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..gains import Gains
from .los import saturate_norm


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class GuidanceInput:
    """What a guidance law sees at one control tick."""

    dt_s: float
    los_enu: np.ndarray  # unit LOS n_t (eq. 5)
    los_elev_rad: float  # q_y (eq. 6)
    los_azim_rad: float  # q_z (eq. 6), from +y toward +x
    d_los_elev_rad: float  # q_y(k) - q_y(k-1)
    d_los_azim_rad: float  # wrapped to (-pi, pi]
    velocity_enu_m_s: np.ndarray
    e_norm: tuple[float, float]  # normalised image error e / f
    R_WC: np.ndarray  # camera -> world
    # elevation (rad) of the image's (top, bottom) edges above the body x axis of a level
    # body: mount pitch +- half the vertical FOV; nan switches the FOV-aware terms off
    fov_edges_rad: tuple[float, float] = (math.nan, math.nan)
    # the DKF's range along the LOS (m) and the target's velocity (ENU, m/s) with the trace of
    # its covariance (m^2/s^2); nan / None when unknown (the midcourse term is then off)
    range_m: float = math.nan
    target_vel_enu_m_s: np.ndarray | None = None
    target_vel_var_m2_s2: float = math.nan
    # the specific force (m/s^2, ENU) of the drag the loop believes its airframe has plus the
    # disturbance observer's d^ (png.believed_drag_floats): the speed ramp overcomes its
    # along-track part
    disturbance_enu_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # the target's acceleration (m/s^2 ENU; the IMM's, onboard/estimation/imm.py; None:
    # unknown) and the airframe's lateral-acceleration limit (m/s^2; nan: the gains' a_max):
    # the augmented law's inputs (onboard/control/apn.py)
    target_accel_enu_m_s2: tuple[float, float, float] | None = None
    accel_limit_m_s2: float = math.nan
    # the rate (rad/s about +z, + left) the target's acceleration turns at (the IMM's CT model)
    target_turn_rate_rad_s: float = 0.0
    # the DKF's range estimate (m) whatever its confidence, the IMM's target speed (m/s);
    # nan without one
    range_est_m: float = math.nan
    target_speed_m_s: float = math.nan
    # the time to go (s) from the DKF's range and the closing speed (nan: unknown), and the
    # airframe's limit in the endgame (m/s^2; nan: accel_limit_m_s2): the augmented law's
    time_to_go_s: float = math.nan
    endgame_accel_limit_m_s2: float = math.nan
    # the speed ramp's reference at most this (m/s; inf: v_max alone), the approach's limit
    # near the ground (onboard/control/clearance.py)
    speed_cap_m_s: float = math.inf


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class GuidanceOutput:
    accel_desired_enu_m_s2: np.ndarray  # a_d, saturated (eq. 17)
    vel_elev_rad: float  # sigma_y (eq. 7), nan when hovering
    vel_azim_rad: float  # sigma_z (eq. 7), nan when hovering
    hovering: bool  # |v| < v_min or moving away from the target: flew along the LOS


def _hover_start(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    # Below v_min the velocity angles are undefined: accelerate along the LOS (DESIGN §3.4).
    a_d = saturate_norm(gains.k_a * inp.los_enu, gains.a_max)
    return GuidanceOutput(a_d, math.nan, math.nan, True)
