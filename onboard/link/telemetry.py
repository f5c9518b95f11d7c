"""The controller-state telemetry the onboard component sends to the ground in one
``DEBUG_FLOAT_ARRAY`` (name ``PRG_CTRL``, array_id 1) per message; the README documents the
layout. Floats only; NaN marks a value that does not exist yet (no detection, no estimate).
"""

from __future__ import annotations

import math

from ..camera_model import CameraModel
from ..datatypes import ControlTelemetry, Detection
from ..enums import GuidanceLaw, LoopMode, RuntimeState, codes, describe_codes

ARRAY_NAME = "PRG_CTRL"
ARRAY_ID = 1
ARRAY_LEN = 58  # DEBUG_FLOAT_ARRAY.data

# (index order) name, unit, meaning
FIELDS: tuple[tuple[str, str, str], ...] = (
    ("t_s", "s", "onboard clock at the control tick"),
    ("state", "-", "runtime state: " + describe_codes(RuntimeState)),
    ("loop_mode", "-", describe_codes(LoopMode)),
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
    ("law", "-", "guidance law: " + describe_codes(GuidanceLaw)),
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
    ("dkf_r_u_px_s", "px/s", "DKF state r_x: image-error rate not explained by rotation, u"),
    ("dkf_r_v_px_s", "px/s", "DKF state r_y, v"),
    ("dkf_var_e_u_px2", "px^2", "DKF covariance diagonal: e_x"),
    ("dkf_var_e_v_px2", "px^2", "e_y"),
    ("dkf_var_r_u_px2_s2", "px^2/s^2", "r_x"),
    ("dkf_var_r_v_px2_s2", "px^2/s^2", "r_y"),
)
INDEX = {name: i for i, (name, _, _) in enumerate(FIELDS)}
FIELD_NAMES_DKF_COV = (
    "dkf_var_e_u_px2",
    "dkf_var_e_v_px2",
    "dkf_var_r_u_px2_s2",
    "dkf_var_r_v_px2_s2",
)
assert len(FIELDS) <= ARRAY_LEN

# MAVLink codes: a member's index in its enumeration's declaration order
STATE_CODES = codes(RuntimeState)
LAW_CODES = codes(GuidanceLaw)
LOOP_MODE_CODES = codes(LoopMode)


def loop_values(tel: ControlTelemetry) -> dict[str, float]:
    """The fields one control tick fills (eq. numbers in FIELDS)."""
    a, w = tel.accel_desired_enu_m_s2, tel.command.body_rates_flu_rad_s
    vals = {
        "loop_mode": LOOP_MODE_CODES.index(tel.mode.value),
        "los_elev_rad": tel.los_elev_rad,
        "los_azim_rad": tel.los_azim_rad,
        "vel_elev_rad": tel.vel_elev_rad,
        "vel_azim_rad": tel.vel_azim_rad,
        "acc_des_e_m_s2": a[0],
        "acc_des_n_m_s2": a[1],
        "acc_des_u_m_s2": a[2],
        "acc_normal_des_m_s2": tel.accel_normal_desired_m_s2,
        "rate_cmd_x_rad_s": w[0],
        "rate_cmd_y_rad_s": w[1],
        "rate_cmd_z_rad_s": w[2],
        "thrust_cmd": tel.command.thrust_normalised,
        "yaw_rate_cmd_rad_s": tel.yaw_rate_cmd_rad_s,
        "dkf_since_det_s": min(tel.dkf_time_since_detection_s, 1e6),
        "dkf_lost": float(tel.dkf_lost),
    }
    if tel.e_est_px is not None:
        vals.update(
            e_est_u_px=tel.e_est_px[0],
            e_est_v_px=tel.e_est_px[1],
            e_rate_u_px_s=tel.e_rate_est_px_s[0],
            e_rate_v_px_s=tel.e_rate_est_px_s[1],
        )
    return vals


def dkf_values(state_px, cov_diag) -> dict[str, float]:
    """The DKF state (e_x, e_y, r_x, r_y) and its covariance diagonal, beyond the estimate
    ``loop_values`` sends (none before the filter starts)."""
    if state_px is None:
        return {}
    vals = {"dkf_r_u_px_s": state_px[2], "dkf_r_v_px_s": state_px[3]}
    if cov_diag is not None:
        vals.update(zip(FIELD_NAMES_DKF_COV, cov_diag, strict=True))
    return vals


def detection_values(det: Detection | None, camera: CameraModel) -> dict[str, float]:
    """The latest detection's image error and capture time (none: no fields)."""
    if det is None:
        return {}
    e = camera.error_px(*det.center_px)
    return {"e_raw_u_px": e[0], "e_raw_v_px": e[1], "raw_capture_t_s": det.capture_time_s}


def pose_values(pos_enu_m, vel_enu_m_s, q_wxyz) -> dict[str, float]:
    """The vehicle state the tick used (ENU, FLU -> ENU quaternion); None: not known yet."""
    vals: dict[str, float] = {}
    if pos_enu_m is not None:
        vals.update(pos_e_m=pos_enu_m[0], pos_n_m=pos_enu_m[1], pos_u_m=pos_enu_m[2])
        vals.update(vel_e_m_s=vel_enu_m_s[0], vel_n_m_s=vel_enu_m_s[1], vel_u_m_s=vel_enu_m_s[2])
    if q_wxyz is not None:
        vals.update(q_w=q_wxyz[0], q_x=q_wxyz[1], q_y=q_wxyz[2], q_z=q_wxyz[3])
    return vals


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
