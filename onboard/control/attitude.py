"""Geometric attitude loop: desired acceleration -> body rates and collective thrust
(paper eqs. 18-24, DESIGN.md §3 steps 9-10).

Written in plain floats and compiled (onboard/jit.py): it runs every control tick in the
simulator and on the vehicle, and numpy's per-call overhead on 3-vectors and 3x3 matrices cost
more than the arithmetic."""

from __future__ import annotations

import math

import numpy as np

from ..datatypes import GRAVITY_M_S2, VehicleParams
from ..gains import Gains
from ..jit import kernel
from .disturbance import feedforward_floats
from .guidance import normal_floats


def desired_thrust_direction(accel_desired_enu_m_s2: np.ndarray) -> np.ndarray:
    """n_fd = (a_d - g) / |a_d - g| (paper eq. 18); straight up if a_d - g vanishes."""
    fx, fy, fz = _thrust_vector(accel_desired_enu_m_s2)
    n = math.sqrt(fx * fx + fy * fy + fz * fz)
    if n < 1e-9:
        return np.array([0.0, 0.0, 1.0])
    return np.array([fx / n, fy / n, fz / n])


def _thrust_vector(a_enu_m_s2) -> tuple[float, float, float]:
    """a_d - g with g = (0, 0, -9.81) ENU, in floats."""
    return float(a_enu_m_s2[0]), float(a_enu_m_s2[1]), float(a_enu_m_s2[2]) + GRAVITY_M_S2


def attitude_command(
    accel_desired_enu_m_s2: np.ndarray,
    R_WB: np.ndarray,
    yaw_rate_rad_s: float,
    gains: Gains,
    vehicle: VehicleParams,
) -> tuple[np.ndarray, float]:
    """Body rates (FLU, rad/s) and thrust normalised to [0, 1] (:func:`attitude_floats`)."""
    a = accel_desired_enu_m_s2
    R = np.asarray(R_WB, dtype=np.float64)
    if R.shape != (3, 3):
        raise ValueError(f"R_WB must be 3x3, not {R.shape}")
    w0, w1, w2, thrust = attitude_floats(
        float(a[0]),
        float(a[1]),
        float(a[2]),
        R,
        float(yaw_rate_rad_s),
        gains.k_R,
        gains.omega_max,
        vehicle.mass_kg,
        vehicle.max_thrust_n,
    )
    return np.array([w0, w1, w2]), thrust


@kernel(
    "UniTuple(float64, 4)(float64, float64, float64, float64[:, :], float64, float64, float64,"
    " float64, float64)"
)
def attitude_floats(
    a0: float,
    a1: float,
    a2: float,
    R_WB: np.ndarray,
    yaw_rate_rad_s: float,
    k_R: float,
    omega_max: float,
    mass_kg: float,
    max_thrust_n: float,
) -> tuple[float, float, float, float]:
    """Body rates (FLU, rad/s) and thrust normalised to [0, 1] for the desired acceleration
    (a0, a1, a2) (ENU, m/s^2) and the attitude ``R_WB`` (3x3, body -> world); compiled.

    R_d = R_tilt R_WB with R_tilt the rotation taking n_f = R_WB e_z onto n_fd by the angle
    phi about the unit axis k (eq. 19); w_1 = -k_R/2 vex(R_d^T R - R^T R_d) (eq. 22);
    w_d = sat(w_1 + (0, 0, r_d), omega_max) (eq. 24); T = m n_f . (a_d - g) clipped to
    [0, T_max] (eq. 23).

    Since R_tilt^T - R_tilt = -2 sin(phi) [k]x (Rodrigues) and R^T [k]x R = [R^T k]x, eq. 22
    is w_1 = k_R sin(phi) R_WB^T k = k_R R_WB^T (n_f x n_fd): no matrix is formed.
    """
    fx, fy, fz = a0, a1, a2 + GRAVITY_M_S2  # a_d - g, g = (0, 0, -9.81) ENU
    n = math.sqrt(fx * fx + fy * fy + fz * fz)
    if n < 1e-9:
        dx, dy, dz = 0.0, 0.0, 1.0
    else:
        dx, dy, dz = fx / n, fy / n, fz / n
    r00, r01, r02 = R_WB[0, 0], R_WB[0, 1], R_WB[0, 2]
    r10, r11, r12 = R_WB[1, 0], R_WB[1, 1], R_WB[1, 2]
    r20, r21, r22 = R_WB[2, 0], R_WB[2, 1], R_WB[2, 2]
    ax, ay, az = r02, r12, r22  # n_f = R_WB e_z
    # sin(phi) k = n_f x n_fd (the axis of R_tilt times the sine of its angle)
    cx, cy, cz = ay * dz - az * dy, az * dx - ax * dz, ax * dy - ay * dx
    s = math.sqrt(cx * cx + cy * cy + cz * cz)
    if s < 1e-9:  # parallel: no tilt; antiparallel: a half turn, sin(pi) k
        c = ax * dx + ay * dy + az * dz
        if c > 0.0:
            cx = cy = cz = 0.0
        else:
            px, py, pz = 0.0, az, -ay  # n_f x e_x
            if px * px + py * py + pz * pz < 1e-12:
                px, py, pz = -az, 0.0, ax  # n_f x e_y
            pn = math.sqrt(px * px + py * py + pz * pz)
            sp = math.sin(math.pi)
            cx, cy, cz = sp * px / pn, sp * py / pn, sp * pz / pn
    k = k_R
    w0 = k * (r00 * cx + r10 * cy + r20 * cz)
    w1 = k * (r01 * cx + r11 * cy + r21 * cz)
    w2 = k * (r02 * cx + r12 * cy + r22 * cz) + yaw_rate_rad_s
    wn = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    lim = omega_max
    if wn > lim > 0.0:  # saturate the norm, keeping the direction (eq. 24)
        g = lim / wn
        w0, w1, w2 = w0 * g, w1 * g, w2 * g
    thrust_n = mass_kg * (ax * fx + ay * fy + az * fz)
    thrust_n = min(max(thrust_n, 0.0), max_thrust_n)
    return w0, w1, w2, thrust_n / max_thrust_n


_COMMAND_SIG = (
    "UniTuple(float64, 6)(float64, float64, float64, boolean, float64, float64, float64, float64,"
    " float64, float64, float64, float64[:, :], float64, float64, float64, float64, float64,"
    " float64)"
)


@kernel(_COMMAND_SIG, uses=(feedforward_floats, normal_floats))
def command_floats(
    a0: float,
    a1: float,
    a2: float,
    feedforward: bool,
    d0: float,
    d1: float,
    d2: float,
    v0: float,
    v1: float,
    v2: float,
    v_min_m_s: float,
    R_WB: np.ndarray,
    yaw_rate_rad_s: float,
    k_R: float,
    omega_max: float,
    mass_kg: float,
    max_thrust_n: float,
    hover_thrust: float,
) -> tuple[float, float, float, float, float, float]:
    """A tick's command from the guidance's a_d = (a0, a1, a2) (ENU, m/s^2), compiled: with
    ``feedforward`` the believed drag and disturbance D = (d0, d1, d2) is cancelled (its normal
    part at speed: ``feedforward_floats`` of the velocity v), :func:`attitude_floats` turns it
    into body rates (FLU, rad/s) and thrust in [0, 1], and the output guard replaces a
    non-finite or out-of-range command by level hover (``hover_thrust``: no rates). Returns
    (w0, w1, w2, thrust, 1 if the guard tripped else 0, |a_d normal to v| m/s^2)."""
    c0, c1, c2 = a0, a1, a2
    if feedforward:
        f0, f1, f2 = feedforward_floats(d0, d1, d2, v0, v1, v2, v_min_m_s)
        c0, c1, c2 = c0 + f0, c1 + f1, c2 + f2
    w0, w1, w2, thrust = attitude_floats(
        c0, c1, c2, R_WB, yaw_rate_rad_s, k_R, omega_max, mass_kg, max_thrust_n
    )
    ok = math.isfinite(w0) and math.isfinite(w1) and math.isfinite(w2)
    ok = ok and math.isfinite(thrust) and 0.0 <= thrust <= 1.0
    guard = 0.0
    if not ok:
        w0 = w1 = w2 = 0.0
        thrust = hover_thrust
        guard = 1.0
    return w0, w1, w2, thrust, guard, normal_floats(a0, a1, a2, v0, v1, v2)
