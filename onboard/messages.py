"""The controller's messages, defined once: each field's name, JSON type, unit, meaning and
its floats on the MAVLink link. Everything else is derived from these definitions:

- the schemas of the ``/control`` and ``/dkf`` channels (onboard/channels/schemas.py; tests
  hold the encoders in onboard/channels/encode.py to them);
- the live telemetry's layout, :data:`onboard.link.telemetry.FIELDS` (one ``DEBUG_FLOAT_ARRAY``
  ``PRG_CTRL``): :data:`TELEMETRY` lists which fields it carries in which order, each
  field's ``wire`` names its floats;
- the units of the recorded fields the dashboard offers as plots (:func:`units`).

(In onboard/, because onboard never imports the ground station.)"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .enums import GuidanceLaw, LoopMode, RuntimeState, describe_codes


@dataclass(frozen=True, slots=True)
class MessageField:
    name: str
    kind: str  # JSON Schema: number | string | boolean | numbers (an array of numbers)
    unit: str
    meaning: str
    wire: tuple[str, ...] = ()  # its floats' names in the MAVLink telemetry; (): not sent
    parts: tuple[str, ...] = ()  # what each element of an array is, e.g. ("east", "north", "up")
    part_units: tuple[str, ...] = ()  # each element's unit when they differ
    codes: type[enum.Enum] | None = None  # a string sent as its code (index in the enum)
    limits: tuple[float, float] | None = None  # a value outside is nonsense: shown as missing

    def element_unit(self, i: int) -> str:
        return self.part_units[i] if self.part_units else self.unit


def _f(name: str, kind: str, unit: str, meaning: str, **kw) -> MessageField:
    return MessageField(name, kind, unit, meaning, **kw)


_ENU = ("east", "north", "up")
_UV = ("u (right)", "v (down)")

CONTROL: tuple[MessageField, ...] = (
    _f("t_s", "number", "s", "control tick time (the sortie's clock; live: the onboard's)",
       wire=("t_s",)),
    _f("mode", "string", "-", "loop mode", wire=("loop_mode",), codes=LoopMode),
    _f("law", "string", "-", "guidance law", wire=("law",), codes=GuidanceLaw),
    _f("los_elev_rad", "number", "rad", "LOS elevation q_y (eq. 6)", wire=("los_elev_rad",)),
    _f("los_azim_rad", "number", "rad", "LOS azimuth q_z (eq. 6)", wire=("los_azim_rad",)),
    _f("vel_elev_rad", "number", "rad", "velocity elevation sigma_y (eq. 7)",
       wire=("vel_elev_rad",)),
    _f("vel_azim_rad", "number", "rad", "velocity azimuth sigma_z (eq. 7)",
       wire=("vel_azim_rad",)),
    _f("accel_desired_m_s2", "numbers", "m/s^2", "desired acceleration a_d, ENU (eq. 17)",
       wire=("acc_des_e_m_s2", "acc_des_n_m_s2", "acc_des_u_m_s2"), parts=_ENU),
    _f("accel_normal_desired_m_s2", "number", "m/s^2", "a_d normal to the velocity",
       wire=("acc_normal_des_m_s2",)),
    _f("accel_normal_m_s2", "number", "m/s^2", "actual acceleration normal to the velocity"),
    _f("body_rates_cmd_rad_s", "numbers", "rad/s", "body-rate command, FLU (eq. 24)",
       wire=("rate_cmd_x_rad_s", "rate_cmd_y_rad_s", "rate_cmd_z_rad_s"),
       parts=("x (roll)", "y (pitch)", "z (yaw)")),
    _f("thrust_cmd", "number", "-", "collective thrust command, normalised 0..1",
       wire=("thrust_cmd",)),
    _f("yaw_rate_cmd_rad_s", "number", "rad/s", "FOV-holding yaw-rate command (eq. 13)",
       wire=("yaw_rate_cmd_rad_s",)),
    _f("e_px", "numbers", "px", "DKF image error estimate (u, v)",
       wire=("e_est_u_px", "e_est_v_px"), parts=_UV),
    _f("e_rate_px_s", "numbers", "px/s", "DKF image error rate (u, v)",
       wire=("e_rate_u_px_s", "e_rate_v_px_s"), parts=_UV),
    _f("speed_m_s", "number", "m/s", "vehicle speed"),
    _f("range_m", "number", "m", "range to the target (null: not reported)"),
    _f("vel_m_s", "numbers", "m/s", "vehicle velocity, ENU",
       wire=("vel_e_m_s", "vel_n_m_s", "vel_u_m_s"), parts=_ENU),
    _f("e_raw_px", "numbers", "px", "latest detection's image error (u, v)",
       wire=("e_raw_u_px", "e_raw_v_px"), parts=_UV),
    _f("raw_capture_t_s", "number", "s", "that detection's capture time",
       wire=("raw_capture_t_s",)),
    _f("speed_cap_m_s", "number", "m/s",
       "approach speed limit near the ground (control/clearance.py; null: none)",
       wire=("speed_cap_m_s",)),
)  # fmt: skip

DKF: tuple[MessageField, ...] = (
    _f("t_s", "number", "s", "control tick time"),
    # its e_x, e_y are the control message's e_px: on the link, only r_x, r_y are added
    _f("state", "numbers", "px, px/s", "DKF state (e_x, e_y, r_x, r_y)",
       wire=("e_est_u_px", "e_est_v_px", "dkf_r_u_px_s", "dkf_r_v_px_s"),
       parts=("e_x", "e_y", "r_x (image-error rate not explained by rotation)", "r_y"),
       part_units=("px", "px", "px/s", "px/s")),
    _f("cov_diag", "numbers", "px^2, px^2/s^2", "DKF covariance diagonal",
       wire=("dkf_var_e_u_px2", "dkf_var_e_v_px2", "dkf_var_r_u_px2_s2", "dkf_var_r_v_px2_s2"),
       parts=("e_x", "e_y", "r_x", "r_y"),
       part_units=("px^2", "px^2", "px^2/s^2", "px^2/s^2")),
    _f("acquired", "boolean", "-", "the loop has had a target estimate"),
    _f("lost", "boolean", "-", "the estimate is lost", wire=("dkf_lost",)),
    _f("time_since_detection_s", "number", "s", "since the last fused detection",
       wire=("dkf_since_det_s",)),
    # the in-flight estimates (onboard/estimation/self_calibration.py)
    _f("target_diameter_m", "number", "m", "in-flight estimate of the target's diameter",
       wire=("selfcal_diam_m",)),
    _f("target_diameter_std_m", "number", "m", "its 1 sigma"),
    _f("camera_offset_s", "number", "s",
       "in-flight estimate of the camera-IMU time offset (stamp minus capture)",
       wire=("selfcal_offset_s",)),
    _f("camera_offset_std_s", "number", "s", "its 1 sigma"),
    _f("target_accel_m_s2", "numbers", "m/s^2",
       "target acceleration, ENU (IMM of its motion; null when it does not run)", parts=_ENU),
    _f("model_probs", "numbers", "-", "IMM model probabilities (CV, CA, coordinated turn)",
       parts=("cv (constant velocity)", "ca (constant acceleration)", "ct (coordinated turn)")),
    _f("target_turn_rate_rad_s", "number", "rad/s",
       "the IMM's coordinated-turn rate, + left (null when it does not run)"),
)  # fmt: skip


def _l(name: str, unit: str, meaning: str, **kw) -> MessageField:
    """A field only the live link carries (one float unless ``wire`` says otherwise)."""
    kind = "numbers" if len(kw.get("wire", ())) > 1 else "number"
    return MessageField(name, kind, unit, meaning, **{"wire": (name,), **kw})


LINK: tuple[MessageField, ...] = (
    _l("state", "-", "runtime state", codes=RuntimeState),
    _l("guard_trips", "-", "output-guard trips (command replaced by hover)"),
    _l("loop_rate_hz", "Hz", "achieved control rate over the last second"),
    _l("loop_jitter_p99_ms", "ms", "p99 of |tick period - nominal| over the last second"),
    _l("overruns", "-", "control ticks whose work took longer than the period (total)"),
    _l("latency_ms", "ms", "capture-to-command latency of the latest fused detection"),
    _l("params_version", "-", "incremented on every applied parameter change"),
    _l("pos_m", "m", "vehicle position the tick used, ENU",
       wire=("pos_e_m", "pos_n_m", "pos_u_m"), parts=_ENU),
    _l("q_wxyz", "-", "attitude quaternion FLU -> ENU",
       wire=("q_w", "q_x", "q_y", "q_z"), parts=("w", "x", "y", "z")),
    _l("image_w_px", "px", "image width", limits=(1.0, 16384.0)),
    _l("image_h_px", "px", "image height", limits=(1.0, 16384.0)),
    _l("f_px", "px", "focal length", limits=(1.0, 16384.0)),
    _l("detections", "-", "detections made (total)"),
    _l("frames", "-", "camera frames received (total)"),
    _l("commands_sent", "-", "SET_ATTITUDE_TARGET messages sent (total)"),
    _l("target_size_frac", "-", "latest detection's width over the image width"),
)  # fmt: skip


def by_name(fields: tuple[MessageField, ...]) -> dict[str, MessageField]:
    return {f.name: f for f in fields}


_C, _D, _L = by_name(CONTROL), by_name(DKF), by_name(LINK)

TELEMETRY: tuple[MessageField, ...] = (
    _C["t_s"], _L["state"], _C["mode"], _C["e_raw_px"], _C["raw_capture_t_s"], _C["e_px"],
    _C["e_rate_px_s"], _C["los_elev_rad"], _C["los_azim_rad"], _C["vel_elev_rad"],
    _C["vel_azim_rad"], _C["accel_desired_m_s2"], _C["accel_normal_desired_m_s2"],
    _C["body_rates_cmd_rad_s"], _C["thrust_cmd"], _C["yaw_rate_cmd_rad_s"],
    _D["time_since_detection_s"], _D["lost"], _L["guard_trips"], _L["loop_rate_hz"],
    _L["loop_jitter_p99_ms"], _L["overruns"], _L["latency_ms"], _C["law"],
    _L["params_version"], _L["pos_m"], _C["vel_m_s"], _L["q_wxyz"], _L["image_w_px"],
    _L["image_h_px"], _L["f_px"], _L["detections"], _L["frames"], _L["commands_sent"],
    _L["target_size_frac"], _D["state"], _D["cov_diag"], _D["target_diameter_m"],
    _D["camera_offset_s"], _C["speed_cap_m_s"],
)  # fmt: skip
"""The fields the MAVLink telemetry carries, in order (their ``wire`` floats; an element
already carried by an earlier field is not sent twice)."""


def wire_layout(fields: tuple[MessageField, ...]) -> tuple[tuple[str, str, str], ...]:
    """(name, unit, meaning) of each float of a flat message made of ``fields``."""
    out: list[tuple[str, str, str]] = []
    seen: set[str] = set()
    for f in fields:
        for i, name in enumerate(f.wire):
            if name in seen:
                continue
            seen.add(name)
            meaning = f"{f.meaning}: {f.parts[i]}" if f.parts else f.meaning
            if f.codes is not None:
                meaning += ": " + describe_codes(f.codes)
            elif f.kind == "boolean":
                meaning += " (1: yes, 0: no)"
            out.append((name, f.element_unit(i), meaning))
    return tuple(out)


def units(fields: tuple[MessageField, ...]) -> dict[str, str]:
    """Unit of each recorded field and of each array element (``name.i``), for the plots."""
    out: dict[str, str] = {}
    for f in fields:
        out[f.name] = f.unit
        for i in range(len(f.parts)):
            out[f"{f.name}.{i}"] = f.element_unit(i)
    return out
