"""Geometric attitude loop: desired acceleration -> body rates and collective thrust
(paper eqs. 18-24, DESIGN.md §3 steps 9-10)."""

from __future__ import annotations

import math

import numpy as np

from ..datatypes import GRAVITY_ENU_M_S2, VehicleParams
from ..gains import Gains
from ..geometry import rotation_between, vex
from .guidance import saturate_norm


def desired_thrust_direction(accel_desired_enu_m_s2: np.ndarray) -> np.ndarray:
    """n_fd = (a_d - g) / |a_d - g| (paper eq. 18); straight up if a_d - g vanishes."""
    f = accel_desired_enu_m_s2 - GRAVITY_ENU_M_S2
    n = math.sqrt(float(f @ f))
    if n < 1e-9:
        return np.array([0.0, 0.0, 1.0])
    return f / n


def attitude_command(
    accel_desired_enu_m_s2: np.ndarray,
    R_WB: np.ndarray,
    yaw_rate_rad_s: float,
    gains: Gains,
    vehicle: VehicleParams,
) -> tuple[np.ndarray, float]:
    """Body rates (FLU, rad/s) and thrust normalised to [0, 1].

    R_d = R_tilt R_WB with R_tilt the rotation taking n_f = R_WB e_z onto n_fd (eq. 19);
    w_1 = -k_R/2 vex(R_d^T R - R^T R_d) (eq. 22); w_d = sat(w_1 + (0, 0, r_d), omega_max)
    (eq. 24); T = m n_f . (a_d - g) clipped to [0, T_max] (eq. 23).
    """
    n_fd = desired_thrust_direction(accel_desired_enu_m_s2)
    n_f = R_WB[:, 2]
    R_d = rotation_between(n_f, n_fd) @ R_WB
    omega_1 = -0.5 * gains.k_R * vex(R_d.T @ R_WB - R_WB.T @ R_d)
    omega = saturate_norm(omega_1 + np.array([0.0, 0.0, yaw_rate_rad_s]), gains.omega_max)
    thrust_n = vehicle.mass_kg * float(n_f @ (accel_desired_enu_m_s2 - GRAVITY_ENU_M_S2))
    thrust_n = min(max(thrust_n, 0.0), vehicle.max_thrust_n)
    return omega, thrust_n / vehicle.max_thrust_n
