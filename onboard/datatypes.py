"""Typed samples, estimates and commands exchanged between the parts of the loop.

Every sample carries the time it was captured (``time_s`` / ``capture_time_s``) on the run's
one clock: simulated time in the simulator, vehicle time in flight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .constants import GRAVITY_M_S2  # declared there, imported from here too
from .enums import LoopMode  # declared there, imported from here too

if TYPE_CHECKING:
    from .estimation.self_calibration import SelfCalEstimate

GRAVITY_ENU_M_S2 = np.array([0.0, 0.0, -GRAVITY_M_S2])


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class VehicleState:
    """What the flight controller reports: position, velocity, attitude, body rates."""

    time_s: float
    position_enu_m: np.ndarray
    velocity_enu_m_s: np.ndarray
    attitude_wxyz: np.ndarray  # body (FLU) -> world (ENU)
    body_rates_flu_rad_s: np.ndarray
    # the time the attitude is of (s, after any propagation to the tick): older than the tick
    # when the attitude stream stalled; None: taken to be of the tick
    attitude_time_s: float | None = None


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class GyroSample:
    time_s: float
    rates_flu_rad_s: np.ndarray


@dataclass(frozen=True, slots=True)
class Detection:
    """One detector result. Pixel coordinates: u right, v down, origin top-left."""

    capture_time_s: float
    center_px: tuple[float, float]
    bbox_px: tuple[float, float, float, float]  # x, y, width, height
    area_px: float
    score: float = 1.0


@dataclass(frozen=True, slots=True)
class VehicleParams:
    """The airframe numbers the attitude loop needs (paper eq. 23)."""

    mass_kg: float = 1.5
    max_thrust_n: float = 3.0 * 1.5 * GRAVITY_M_S2

    @classmethod
    def from_hover_thrust(cls, hover_thrust_normalised: float) -> VehicleParams:
        """The airframe as the operator knows it: only its hover thrust (PRG_HOVER_THR; the
        loop uses mass and maximum thrust only as their ratio), mass 1 kg."""
        return cls(mass_kg=1.0, max_thrust_n=GRAVITY_M_S2 / hover_thrust_normalised)

    @property
    def hover_thrust_normalised(self) -> float:
        return self.mass_kg * GRAVITY_M_S2 / self.max_thrust_n


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class RateThrustCommand:
    """Body rates (FLU, rad/s) and collective thrust normalised to [0, 1] for PX4."""

    time_s: float
    body_rates_flu_rad_s: np.ndarray
    thrust_normalised: float


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class ControlTelemetry:
    """What one control tick computed; the ground station plots and records this."""

    time_s: float
    mode: LoopMode
    law: str
    e_est_px: tuple[float, float] | None
    e_rate_est_px_s: tuple[float, float] | None
    los_elev_rad: float
    los_azim_rad: float
    vel_elev_rad: float
    vel_azim_rad: float
    accel_desired_enu_m_s2: np.ndarray
    accel_normal_desired_m_s2: float
    yaw_rate_cmd_rad_s: float
    command: RateThrustCommand
    dkf_time_since_detection_s: float
    dkf_lost: bool
    guard_tripped: bool
    # the in-flight target size and camera-offset estimates (onboard/estimation/self_calibration.py)
    self_cal: SelfCalEstimate | None = None
    # the IMM of the target's motion (onboard/estimation/imm.py), None when it does not run:
    # its acceleration (m/s^2 ENU), the model probabilities (cv, ca, ct), CT's turn rate (rad/s)
    target_accel_enu_m_s2: tuple[float, float, float] | None = None
    motion_model_probs: tuple[float, float, float] | None = None
    target_turn_rate_rad_s: float | None = None
    # the approach's speed limit near the ground (onboard/control/clearance.py), m/s; inf: none
    speed_cap_m_s: float = math.inf
