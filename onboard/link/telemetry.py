"""The controller-state telemetry the onboard component sends to the ground in one
``DEBUG_FLOAT_ARRAY`` (name ``PRG_CTRL``, array_id 1) per message; the README documents the
layout. Floats only; NaN marks a value that does not exist yet (no detection, no estimate).
"""

from __future__ import annotations

import math

ARRAY_NAME = "PRG_CTRL"
ARRAY_ID = 1
ARRAY_LEN = 58  # DEBUG_FLOAT_ARRAY.data

# (index order) name, unit, meaning
FIELDS: tuple[tuple[str, str, str], ...] = (
    ("t_s", "s", "onboard clock at the control tick"),
    ("state", "-", "runtime state code (see STATE_CODES)"),
    ("loop_mode", "-", "0 waiting, 1 tracking, 2 lost, 3 brake (abort)"),
    ("e_raw_u_px", "px", "latest detection: image error, u (right)"),
    ("e_raw_v_px", "px", "latest detection: image error, v (down)"),
    ("raw_capture_t_s", "s", "capture time of that detection (onboard clock)"),
    ("e_est_u_px", "px", "DKF image error estimate, u"),
    ("e_est_v_px", "px", "DKF image error estimate, v"),
    ("e_rate_u_px_s", "px/s", "DKF image error rate, u"),
    ("e_rate_v_px_s", "px/s", "DKF image error rate, v"),
    ("los_elev_rad", "rad", "LOS elevation q_y (eq. 6)"),
    ("los_azim_rad", "rad", "LOS azimuth q_z (eq. 7)"),
    ("vel_elev_rad", "rad", "velocity elevation"),
    ("vel_azim_rad", "rad", "velocity azimuth"),
    ("acc_des_e_m_s2", "m/s^2", "desired acceleration, east (eq. 17)"),
    ("acc_des_n_m_s2", "m/s^2", "desired acceleration, north"),
    ("acc_des_u_m_s2", "m/s^2", "desired acceleration, up"),
    ("acc_normal_des_m_s2", "m/s^2", "desired acceleration normal to the velocity"),
    ("rate_cmd_x_rad_s", "rad/s", "body-rate command, FLU x (roll)"),
    ("rate_cmd_y_rad_s", "rad/s", "body-rate command, FLU y"),
    ("rate_cmd_z_rad_s", "rad/s", "body-rate command, FLU z (yaw)"),
    ("thrust_cmd", "-", "collective thrust command, normalised 0..1"),
    ("yaw_rate_cmd_rad_s", "rad/s", "FOV-holding yaw-rate command (eq. 13)"),
    ("dkf_since_det_s", "s", "time since the last fused detection"),
    ("dkf_lost", "-", "1 when the DKF estimate is lost"),
    ("guard_trips", "-", "output-guard trips (command replaced by hover)"),
    ("loop_rate_hz", "Hz", "achieved control rate over the last second"),
    ("loop_jitter_p99_ms", "ms", "p99 of |tick period - nominal| over the last second"),
    ("overruns", "-", "control ticks whose work took longer than the period (total)"),
    ("latency_ms", "ms", "capture-to-command latency of the latest fused detection"),
    ("law", "-", "guidance law: 0 png, 1 pg, 2 ibvs"),
    ("params_version", "-", "incremented on every applied parameter change"),
    ("pos_e_m", "m", "vehicle position the tick used, east"),
    ("pos_n_m", "m", "north"),
    ("pos_u_m", "m", "up"),
    ("vel_e_m_s", "m/s", "vehicle velocity, east"),
    ("vel_n_m_s", "m/s", "north"),
    ("vel_u_m_s", "m/s", "up"),
    ("q_w", "-", "attitude quaternion FLU -> ENU, w"),
    ("q_x", "-", "x"),
    ("q_y", "-", "y"),
    ("q_z", "-", "z"),
    ("image_w_px", "px", "image width"),
    ("image_h_px", "px", "image height"),
    ("f_px", "px", "focal length"),
    ("detections", "-", "detections made (total)"),
    ("frames", "-", "camera frames received (total)"),
    ("commands_sent", "-", "SET_ATTITUDE_TARGET messages sent (total)"),
    ("target_size_frac", "-", "latest detection's width over the image width"),
)
INDEX = {name: i for i, (name, _, _) in enumerate(FIELDS)}
assert len(FIELDS) <= ARRAY_LEN

STATE_CODES = (
    "link_down",
    "waiting_target",
    "ready",
    "starting",
    "intercept",
    "braking",
    "finished",
    "link_lost",
)
LAW_CODES = ("png", "pg", "ibvs")
LOOP_MODE_CODES = ("waiting", "tracking", "lost", "brake")


def pack(values: dict[str, float]) -> list[float]:
    """The 58 floats of one message; absent fields are NaN, unknown names an error."""
    out = [math.nan] * ARRAY_LEN
    for k, v in values.items():
        out[INDEX[k]] = float(v) if v is not None else math.nan
    return out


def unpack(data) -> dict[str, float | None]:
    """Field name -> value (None for NaN)."""
    return {
        name: (None if not math.isfinite(float(data[i])) else float(data[i]))
        for i, (name, _, _) in enumerate(FIELDS)
    }
