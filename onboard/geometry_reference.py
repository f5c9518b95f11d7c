"""The rotation and camera kernels (:mod:`.geometry`, :mod:`.camera_model`) written with
numpy vectors, 3x3 matrices and quaternions (w, x, y, z) as in the paper and DESIGN.md §1: the
specification the compiled kernels are checked against (tests/test_kernel_references.py)."""

from __future__ import annotations

import math

import numpy as np

from .geometry import hat, vex


def wrap_pi(angle_rad: float) -> float:
    """The angle in (-pi, pi] (nan when not finite)."""
    if not math.isfinite(angle_rad):
        return math.nan
    a = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if a == -math.pi else a


def rotation_of_quaternion(q: np.ndarray) -> np.ndarray:
    """R(q) = (w^2 - |u|^2) I + 2 u u^T + 2 w [u]x for a unit quaternion q = (w, u)."""
    w, u = q[0], q[1:]
    return (w * w - u @ u) * np.eye(3) + 2.0 * np.outer(u, u) + 2.0 * w * hat(u)


def camera_attitude(q: np.ndarray, R_BC: np.ndarray) -> np.ndarray:
    """R_WC = R_WB R_BC, R_WB = R(q) (the LOS of eq. 5 goes through it)."""
    return rotation_of_quaternion(q) @ R_BC


def quaternion_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product: (a_w b_w - a_u . b_u, a_w b_u + b_w a_u + a_u x b_u)."""
    return np.array(
        [a[0] * b[0] - a[1:] @ b[1:], *(a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:]))]
    )


def quaternion_exp(theta: np.ndarray) -> np.ndarray:
    """The unit quaternion of the rotation vector theta: (cos(|theta|/2), sin(|theta|/2)
    theta / |theta|), to first order (1, theta / 2) below 1e-12 rad."""
    angle = float(np.linalg.norm(theta))
    if angle < 1e-12:
        return np.array([1.0, *(0.5 * theta)])
    return np.array([math.cos(0.5 * angle), *(math.sin(0.5 * angle) / angle * theta)])


def propagated_attitude(q: np.ndarray, omega_flu: np.ndarray, dt_s: float) -> np.ndarray:
    """q exp(omega dt), renormalised: the attitude after dt at constant body rates."""
    p = quaternion_product(q, quaternion_exp(omega_flu * dt_s))
    return p / np.linalg.norm(p)


def carried_attitude(
    now_s: float,
    q: np.ndarray,
    q_time_s: float,
    omega_flu: np.ndarray,
    max_dt_s: float,
    max_rate_rad_s: float,
) -> tuple[np.ndarray, float]:
    """The attitude sampled at ``q_time_s`` carried to ``now_s`` at the body rates, by at most
    ``max_dt_s`` (never back), and not at all at rates above ``max_rate_rad_s`` or not finite;
    with the time it is of."""
    dt = min(max(now_s - q_time_s, 0.0), max_dt_s)
    if not np.linalg.norm(omega_flu) <= max_rate_rad_s:
        return q, q_time_s
    if dt != 0.0:
        q = propagated_attitude(q, omega_flu, dt)
    return q, q_time_s + dt


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """log(R) as a rotation vector: angle atan2(sin, cos) about vex(R - R^T) / 2 (below pi)."""
    s_axis = 0.5 * vex(R - R.T)
    s = float(np.linalg.norm(s_axis))
    if s <= 1e-12:
        return s_axis
    return math.atan2(s, 0.5 * (np.trace(R) - 1.0)) / s * s_axis


def attitude_jump(R0: np.ndarray, R1: np.ndarray, omega_flu: np.ndarray, dt_s: float) -> float:
    """|log(R0^T R1) - omega dt|: how far R1 is from R0 turned by the body rates for dt."""
    return float(np.linalg.norm(rotation_vector(R0.T @ R1) - omega_flu * dt_s))


def pixel_of(p_C: np.ndarray, f_px: float, c_px: np.ndarray) -> np.ndarray | None:
    """The pinhole projection (u, v) = c + f (x / z, y / z) of a camera-frame point (eq. 3),
    None behind the camera (z <= 1 um)."""
    if p_C[2] <= 1e-6:
        return None
    return c_px + f_px * p_C[:2] / p_C[2]
