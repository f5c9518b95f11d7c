"""The attitude loop's and the disturbance observer's kernels (:mod:`.attitude`,
:mod:`.disturbance`) written as the paper writes them: 3x3 rotation matrices, numpy vectors
(world ENU, body FLU), named gains. The specification the compiled kernels are checked
against (tests/test_kernel_references.py); nothing on the flight path calls them."""

from __future__ import annotations

import math

import numpy as np

from ..datatypes import GRAVITY_M_S2
from ..gains import Gains
from ..geometry import rotation_between, vex
from .guidance_reference import normal_part, saturate

G_ENU = np.array([0.0, 0.0, -GRAVITY_M_S2])
E_Z = np.array([0.0, 0.0, 1.0])


def attitude(
    a_d: np.ndarray,
    R: np.ndarray,
    yaw_rate_rad_s: float,
    gains: Gains,
    mass_kg: float,
    max_thrust_n: float,
) -> tuple[np.ndarray, float]:
    """Body rates (rad/s FLU) and normalised thrust for the desired acceleration a_d:

    n_fd = (a_d - g) / |a_d - g| (eq. 18; up when it vanishes), n_f = R e_z;
    R_d = R_tilt R, R_tilt the smallest rotation taking n_f onto n_fd (eq. 19);
    w_1 = -k_R / 2 vex(R_d^T R - R^T R_d) (eq. 22); w_d = sat(w_1 + (0, 0, r_d), omega_max)
    (eq. 24); T = m n_f . (a_d - g) clipped to [0, T_max] (eq. 23), over T_max."""
    f = a_d - G_ENU
    n_fd = E_Z if np.linalg.norm(f) < 1e-9 else f / np.linalg.norm(f)
    n_f = R @ E_Z
    R_d = rotation_between(n_f, n_fd) @ R
    w_1 = -0.5 * gains.k_R * vex(R_d.T @ R - R.T @ R_d)
    w_d = saturate(w_1 + np.array([0.0, 0.0, yaw_rate_rad_s]), gains.omega_max)
    thrust_n = min(max(mass_kg * float(n_f @ f), 0.0), max_thrust_n)
    return w_d, thrust_n / max_thrust_n


def feedforward(d_hat: np.ndarray, v: np.ndarray, v_min_m_s: float) -> np.ndarray:
    """-d^ normal to the velocity; its along-track part kept only near hover, fading out from
    |v| = v_min to 2 v_min (the speed ramp, eq. 14, owns the tangential channel)."""
    speed = float(np.linalg.norm(v))
    keep = min(max(2.0 - speed / v_min_m_s, 0.0), 1.0) if v_min_m_s > 0.0 else 0.0
    if keep >= 1.0 or speed < 1e-9:
        return -d_hat
    v_hat = v / speed
    return -d_hat + (1.0 - keep) * float(d_hat @ v_hat) * v_hat


def command(
    a_d: np.ndarray,
    d_hat: np.ndarray | None,
    v: np.ndarray,
    R: np.ndarray,
    yaw_rate_rad_s: float,
    gains: Gains,
    mass_kg: float,
    max_thrust_n: float,
    hover_thrust: float,
) -> tuple[np.ndarray, float, bool, float]:
    """A tick's command: a_d plus the disturbance feed-forward (when d^ is given), through
    :func:`attitude`; a non-finite or out-of-range result becomes level hover (the output
    guard). Returns (rates, thrust, guard tripped, |a_d normal to v|)."""
    a = a_d if d_hat is None else a_d + feedforward(d_hat, v, gains.v_min)
    w, thrust = attitude(a, R, yaw_rate_rad_s, gains, mass_kg, max_thrust_n)
    ok = bool(np.all(np.isfinite(w))) and math.isfinite(thrust) and 0.0 <= thrust <= 1.0
    if not ok:
        w, thrust = np.zeros(3), hover_thrust
    return w, thrust, not ok, normal_part(a_d, v)


def observer_step(
    dt_s: float,
    thrust_n: float,
    thrust_cmd_n: float,
    tau_s: float,
    mass_kg: float,
    drag_per_mass_1_s: float,
    z_prev: np.ndarray,
    z: np.ndarray,
    v_hat: np.ndarray,
    d_hat: np.ndarray,
    v: np.ndarray,
    max_innovation_m_s: float,
    bandwidth_rad_s: float,
    start_factor: float,
    elapsed_s: float,
    max_m_s2: float,
) -> tuple[float, float, np.ndarray, np.ndarray]:
    """One step of the extended state observer on (v, d) (onboard/control/disturbance.py):

    the thrust through the motors' first-order lag (its mean over the step and its end value);
    f = (T_mean / m) (z_prev + z) / 2 - g e_z - c v^; v_pred = v^ + (f + d^) dt;
    r = v - v_pred (beyond ``max_innovation``: a reset, elapsed -1, v^ and d^ kept);
    w = max(bandwidth, start_factor / elapsed), p = exp(-w dt);
    v^' = v_pred + (1 - p^2) r, d^' = d^ + (1 - p)^2 / dt r, |d^'| clamped to ``max_m_s2``.
    Returns (thrust after the step, elapsed, v^', d^')."""
    if tau_s > 0.0:
        decay = math.exp(-dt_s / tau_s)
        t_mean = thrust_cmd_n + (thrust_n - thrust_cmd_n) * tau_s / dt_s * (1.0 - decay)
        thrust_n = thrust_cmd_n + (thrust_n - thrust_cmd_n) * decay
    else:
        t_mean = thrust_n = thrust_cmd_n
    f = t_mean / mass_kg * 0.5 * (z_prev + z) + G_ENU - drag_per_mass_1_s * v_hat
    v_pred = v_hat + (f + d_hat) * dt_s
    r = v - v_pred
    if np.linalg.norm(r) > max_innovation_m_s:
        return thrust_n, -1.0, v_hat, d_hat
    elapsed_s += dt_s
    w = max(bandwidth_rad_s, start_factor / elapsed_s)
    p = math.exp(-w * dt_s)
    v_new = v_pred + (1.0 - p * p) * r
    d_new = d_hat + (1.0 - p) ** 2 / dt_s * r
    n = float(np.linalg.norm(d_new))
    if n > max_m_s2:
        d_new = d_new * (max_m_s2 / n) if n > 0.0 else np.zeros(3)
    return thrust_n, elapsed_s, v_new, d_new
