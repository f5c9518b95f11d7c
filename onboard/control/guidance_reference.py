"""The guidance kernels (:mod:`.los`, :mod:`.png`) written as the paper writes them: numpy
vectors in world ENU, named gains (:class:`~onboard.gains.Gains`), one function per step of
the method. They are the specification the compiled kernels are checked against
(tests/test_kernel_references.py); nothing on the flight path calls them.

Notation: n_t the unit line of sight, q_y / q_z its elevation / azimuth, sigma_y / sigma_z
those of the velocity v, e the image error (px), f the focal length (px).
"""

from __future__ import annotations

import math

import numpy as np

from ..datatypes import GRAVITY_M_S2
from ..gains import Gains
from ..geometry_reference import wrap_pi

PITCH_LIMIT_RAD = math.radians(60.0)  # the FOV guard's bound on the pitch it asks for


def unit(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x)


def saturate(x: np.ndarray, limit: float) -> np.ndarray:
    """x scaled down to norm ``limit`` when longer (direction kept; ``limit <= 0``: no limit)."""
    n = float(np.linalg.norm(x))
    return x * (limit / n) if n > limit > 0.0 else x


def line_of_sight(e_norm: np.ndarray, R_WC: np.ndarray) -> np.ndarray:
    """n_t = R_WC r_C / |r_C| with r_C = (e_x / f, e_y / f, 1) (eq. 5)."""
    return unit(R_WC @ np.array([e_norm[0], e_norm[1], 1.0]))


def direction_angles(n: np.ndarray) -> tuple[float, float]:
    """(elevation, azimuth) of a direction: q_y = atan2(n_z, |n_xy|), q_z = atan2(n_x, n_y)
    (eqs. 6-7, azimuth from north toward east)."""
    return math.atan2(n[2], math.hypot(n[0], n[1])), math.atan2(n[0], n[1])


def direction_from_angles(elev_rad: float, azim_rad: float) -> np.ndarray:
    """n = (cos s_y sin s_z, cos s_y cos s_z, sin s_y) (eq. 9)."""
    return np.array(
        [
            math.cos(elev_rad) * math.sin(azim_rad),
            math.cos(elev_rad) * math.cos(azim_rad),
            math.sin(elev_rad),
        ]
    )


def los_change(q_now: tuple[float, float], q_prev: tuple[float, float]) -> tuple[float, float]:
    """(Delta q_y, Delta q_z) between two ticks, the azimuth's wrapped to (-pi, pi] (eq. 8)."""
    return q_now[0] - q_prev[0], wrap_pi(q_now[1] - q_prev[1])


def smoothed_los_change(prev_rad: float, dq_rad: float, dt_s: float, tau_s: float) -> float:
    """First-order low-pass of Delta q: prev + dt / (tau + dt) (Delta q - prev); Delta q itself
    when ``tau_s`` <= 0 or there is no previous value (nan)."""
    if tau_s <= 0.0 or not math.isfinite(prev_rad):
        return dq_rad
    return prev_rad + dt_s / (tau_s + dt_s) * (dq_rad - prev_rad)


def los_terms(
    e_px: np.ndarray,
    f_px: float,
    R_WC: np.ndarray,
    e_prev_px: np.ndarray | None,
    R_WC_prev: np.ndarray,
    dt_s: float,
    hold_s: float | None,
    tau_los_s: float,
    filt: tuple[float, float],
    flown: tuple[float, float, float],
    max_late_carry: float,
) -> tuple[np.ndarray, float, float, float, float, tuple, tuple]:
    """One tick's LOS terms: n_t (eq. 5) and (q_y, q_z) (eq. 6) of the image estimate e, and
    Delta q (eq. 8) against the previous tick's estimate (0 without one). With the low-pass on
    (tau_los > 0) Delta q is taken as a rate over dt per hold and smoothed; otherwise, given
    the hold, the part of the last command's turn not flown (it was held dt instead of its own
    hold) is carried into this one, at most ``max_late_carry`` holds' worth when late.
    Returns (n_t, q_y, q_z, dq_y, dq_z, filter state, (flown dq_y, dq_z, hold))."""
    n_t = line_of_sight(e_px / f_px, R_WC)
    q = direction_angles(n_t)
    dq = np.zeros(2)
    if e_prev_px is not None:
        q_prev = direction_angles(line_of_sight(e_prev_px / f_px, R_WC_prev))
        dq = np.array(los_change(q, q_prev))
        if hold_s is not None and tau_los_s > 0.0 and hold_s != dt_s:
            dq = dq * (hold_s / dt_s)
    if tau_los_s > 0.0:
        dq = np.array([smoothed_los_change(filt[i], dq[i], dt_s, tau_los_s) for i in range(2)])
        filt = (dq[0], dq[1])
    elif hold_s is not None:
        flown_dq, flown_hold = np.array(flown[:2]), flown[2]
        if not math.isnan(flown_hold) and dt_s != flown_hold:
            dq = dq + flown_dq * max(1.0 - dt_s / flown_hold, -max_late_carry)
        flown = (dq[0], dq[1], hold_s)
    return n_t, q[0], q[1], dq[0], dq[1], filt, flown


def normal_part(a: np.ndarray, v: np.ndarray) -> float:
    """|a - (a . v^) v^|, the part of a normal to v (all of a when v vanishes)."""
    if float(v @ v) < 1e-12:
        return float(np.linalg.norm(a))
    return float(np.linalg.norm(a - (a @ v) / (v @ v) * v))


def ramped_speed(speed_m_s: float, dt_s: float, gains: Gains) -> float:
    """|v_d| = |v| + a_t dt with a_t = clip(k_brake (v_max - |v|), -k_a, k_a) (eq. 14 with the
    speed hold near v_max)."""
    a_t = min(max(gains.k_brake * (gains.v_max - speed_m_s), -gains.k_a), gains.k_a)
    return speed_m_s + a_t * dt_s


def min_pitch(q_y: float, top_edge_rad: float, margin_rad: float) -> float:
    """The lowest body pitch that keeps a LOS of elevation q_y ``margin_rad`` below the image's
    top edge (``top_edge_rad`` above body x), within +-60 deg."""
    return min(max(q_y - (top_edge_rad - margin_rad), -PITCH_LIMIT_RAD), PITCH_LIMIT_RAD)


def fov_guard(
    a_d: np.ndarray,
    camera_axis: np.ndarray,
    top_edge_rad: float,
    q_y: float,
    gains: Gains,
    limit: float | None = None,
) -> tuple[bool, np.ndarray]:
    """Cap the forward part a_f of a_d (along the camera's horizontal heading h) at the value
    whose steady pitch, atan(a_f / (g + a_z)) (eqs. 16, 18), keeps the LOS ``fov_margin``
    inside the top edge, and at no less than 0; then saturate to ``limit`` (a_max unless
    given). Returns (whether it acted, a_d)."""
    margin = math.radians(gains.fov_margin)
    if margin <= 0.0 or not math.isfinite(top_edge_rad):
        return False, a_d
    heading = camera_axis[:2]
    if math.hypot(heading[0], heading[1]) < 1e-6:
        return False, a_d
    h = np.array([*unit(heading), 0.0])
    a_f = float(a_d @ h)
    g_z = max(GRAVITY_M_S2 + a_d[2], 0.1 * GRAVITY_M_S2)
    a_f_max = max(-g_z * math.tan(min_pitch(q_y, top_edge_rad, margin)), 0.0)
    if a_f <= a_f_max:
        return False, a_d
    return True, saturate(a_d + (a_f_max - a_f) * h, gains.a_max if limit is None else limit)


def edge_margin(fov_edges_rad: tuple[float, float], camera_axis: np.ndarray, q_y: float) -> float:
    """Angle between the LOS and the nearer of the image's top and bottom edges at the
    camera's current elevation (negative outside the vertical FOV; nan with unknown edges)."""
    top, bottom = fov_edges_rad
    if not (math.isfinite(top) and math.isfinite(bottom)):
        return math.nan
    elev, _ = direction_angles(camera_axis)
    half = 0.5 * (top - bottom)
    return min(elev + half - q_y, q_y - (elev - half))


def pursuit_weight(
    fov_edges_rad: tuple[float, float], camera_axis: np.ndarray, q_y: float, gains: Gains
) -> float:
    """0 while the LOS is more than ``pur_zone`` inside the top and bottom edges, rising
    linearly to 1 at the edge (0 when ``pur_zone`` or ``k_pur`` is 0)."""
    zone = math.radians(gains.pur_zone)
    if zone <= 0.0 or gains.k_pur <= 0.0:
        return 0.0
    m = edge_margin(fov_edges_rad, camera_axis, q_y)
    if not math.isfinite(m):
        return 0.0
    return min(max(1.0 - m / zone, 0.0), 1.0)


def midcourse_weight(range_m: float, gains: Gains) -> float:
    """0 within r_mid, rising linearly to 1 at 2 r_mid (0 when tau_zem = 0 or range unknown)."""
    if gains.tau_zem <= 0.0 or not math.isfinite(range_m):
        return 0.0
    return min(max(range_m / gains.r_mid - 1.0, 0.0), 1.0)


def zem_nulling_accel(
    v: np.ndarray, v_t: np.ndarray | None, var_v: float, n_t: np.ndarray, gains: Gains
) -> np.ndarray:
    """a = -v_perp / tau_zem, v_perp the velocity relative to the target normal to the LOS,
    the target's velocity shrunk by its uncertainty: |v_t|^2 / (|v_t|^2 + tr P_v)."""
    v_rel = v
    if v_t is not None:
        vt2 = float(v_t @ v_t)
        shrink = vt2 / (vt2 + var_v) if math.isfinite(var_v) and vt2 + var_v > 0.0 else 0.0
        v_rel = v - shrink * v_t
    v_perp = v_rel - (v_rel @ n_t) * n_t
    return -v_perp / gains.tau_zem


def png(
    dt_s: float,
    n_t: np.ndarray,
    q_y: float,
    dq: tuple[float, float],
    v: np.ndarray,
    camera_axis: np.ndarray,
    fov_edges_rad: tuple[float, float],
    range_m: float,
    v_t: np.ndarray | None,
    var_v: float,
    gains: Gains,
    drag: np.ndarray | None = None,
) -> tuple[np.ndarray, float, float, bool]:
    """The proposed law. Below v_min, or moving away from the target (v . n_t < 0: PN has
    no LOS rate to turn on a target behind, and the speed ramp would push along the
    velocity), fly along the LOS: a_d = sat(k_a n_t, a_max). Otherwise
    the velocity angles (eq. 7) turned by K times the LOS change (eq. 8; faded out by the
    midcourse weight w_mid far away), the desired direction n_d (eq. 9), bent toward the LOS
    near the image's top or bottom edge (pursuit bias), the speed ramp (eq. 14), the midcourse
    ZEM-nulling velocity, a_d = sat((v_d - v) / dt, a_max) (eq. 17) plus the along-track
    drag feed-forward a_drag v^ (a_drag = min(max(-D . v^, 0), a_max), D the believed drag and
    disturbance ``drag``), and the FOV guard with the limit a_max + a_drag.
    Returns (a_d, sigma_y, sigma_z, hovering)."""
    top = fov_edges_rad[0]
    speed = float(np.linalg.norm(v))
    if speed < gains.v_min or float(v @ n_t) < 0.0:
        a_d = saturate(gains.k_a * n_t, gains.a_max)
        return fov_guard(a_d, camera_axis, top, q_y, gains)[1], math.nan, math.nan, True
    v_hat = v / speed
    sigma_y, sigma_z = direction_angles(v_hat)
    w_mid = midcourse_weight(range_m, gains)
    sigma_yd = sigma_y + (1.0 - w_mid) * gains.K_y * dq[0]
    sigma_zd = sigma_z + (1.0 - w_mid) * gains.K_z * dq[1]
    n_d = direction_from_angles(sigma_yd, sigma_zd)
    w = pursuit_weight(fov_edges_rad, camera_axis, q_y, gains)
    if w > 0.0:
        n_d = unit(n_d + w * gains.k_pur * dt_s * (n_t - v_hat))
    v_d = ramped_speed(speed, dt_s, gains) * n_d
    if w_mid > 0.0:
        v_d = v_d + w_mid * dt_s * zem_nulling_accel(v, v_t, var_v, n_t, gains)
    a_d = saturate((v_d - v) / dt_s, gains.a_max)
    a_drag = 0.0 if drag is None else min(max(-float(drag @ v_hat), 0.0), gains.a_max)
    a_d = a_d + a_drag * v_hat
    lim = gains.a_max + a_drag
    return fov_guard(a_d, camera_axis, top, q_y, gains, lim)[1], sigma_y, sigma_z, False


def believed_drag(v: np.ndarray, z: np.ndarray, d_hat: np.ndarray, k_drag: float) -> np.ndarray:
    """The drag and disturbance the loop believes: EKF2's rotor-drag model -k_drag (v - (v . z)
    z) (z the thrust axis) plus the observer's d^."""
    return d_hat - k_drag * (v - float(v @ z) * z)
