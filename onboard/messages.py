"""The recorded controller messages, defined once: each field's name, JSON type, unit and
meaning. The MCAP schemas (groundstation/recording/schemas.py) are derived from these, and
tests hold the encoders (groundstation/recording/encode.py) to them; the live telemetry's
layout is :data:`onboard.link.telemetry.FIELDS`. (In onboard/, because onboard never imports
the ground station.)"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class MessageField:
    name: str
    kind: str  # JSON Schema: number | string | boolean | numbers (an array of numbers)
    unit: str
    meaning: str


def _f(name: str, kind: str, unit: str, meaning: str) -> MessageField:
    return MessageField(name, kind, unit, meaning)


CONTROL: tuple[MessageField, ...] = (
    _f("t_s", "number", "s", "control tick time (the sortie's clock)"),
    _f("mode", "string", "-", "loop mode (onboard.enums.LoopMode)"),
    _f("law", "string", "-", "guidance law (onboard.enums.GuidanceLaw)"),
    _f("los_elev_rad", "number", "rad", "LOS elevation q_y (eq. 6)"),
    _f("los_azim_rad", "number", "rad", "LOS azimuth q_z (eq. 6)"),
    _f("vel_elev_rad", "number", "rad", "velocity elevation sigma_y (eq. 7)"),
    _f("vel_azim_rad", "number", "rad", "velocity azimuth sigma_z (eq. 7)"),
    _f("accel_desired_m_s2", "numbers", "m/s^2", "desired acceleration a_d, ENU (eq. 17)"),
    _f("accel_normal_desired_m_s2", "number", "m/s^2", "a_d normal to the velocity"),
    _f("accel_normal_m_s2", "number", "m/s^2", "actual acceleration normal to the velocity"),
    _f("body_rates_cmd_rad_s", "numbers", "rad/s", "body-rate command, FLU (eq. 24)"),
    _f("thrust_cmd", "number", "-", "collective thrust command, normalised 0..1"),
    _f("yaw_rate_cmd_rad_s", "number", "rad/s", "FOV-holding yaw-rate command (eq. 13)"),
    _f("e_px", "numbers", "px", "DKF image error estimate (u, v)"),
    _f("e_rate_px_s", "numbers", "px/s", "DKF image error rate (u, v)"),
    _f("speed_m_s", "number", "m/s", "vehicle speed"),
    _f("range_m", "number", "m", "range to the target (null: not reported)"),
    _f("vel_m_s", "numbers", "m/s", "vehicle velocity, ENU"),
    _f("e_raw_px", "numbers", "px", "latest detection's image error (u, v)"),
    _f("raw_capture_t_s", "number", "s", "that detection's capture time"),
)

DKF: tuple[MessageField, ...] = (
    _f("t_s", "number", "s", "control tick time"),
    _f("state", "numbers", "px, px/s", "DKF state (e_x, e_y, r_x, r_y)"),
    _f("cov_diag", "numbers", "px^2, px^2/s^2", "its covariance diagonal"),
    _f("acquired", "boolean", "-", "the loop has had a target estimate"),
    _f("lost", "boolean", "-", "the estimate is lost"),
    _f("time_since_detection_s", "number", "s", "since the last fused detection"),
)
