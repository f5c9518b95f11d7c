"""The controller-state telemetry the onboard component sends to the ground in one
``DEBUG_FLOAT_ARRAY`` (name ``PRG_CTRL``, array_id 1) per message; its layout is derived from
the message definitions (:data:`onboard.messages.TELEMETRY`) and docs/flying.md documents it.
Floats only; NaN marks a value that does not exist yet (no detection, no estimate).
"""

from __future__ import annotations

import math

from .. import messages
from ..camera_model import CameraModel
from ..datatypes import ControlTelemetry, Detection
from ..enums import GuidanceLaw, LoopMode, RuntimeState, codes

ARRAY_NAME = "PRG_CTRL"
ARRAY_ID = 1
ARRAY_LEN = 58  # DEBUG_FLOAT_ARRAY.data

# (index order) name, unit, meaning: derived from the one definition in onboard/messages.py
FIELDS: tuple[tuple[str, str, str], ...] = messages.wire_layout(messages.TELEMETRY)
INDEX = {name: i for i, (name, _, _) in enumerate(FIELDS)}
_C, _D = messages.by_name(messages.CONTROL), messages.by_name(messages.DKF)
_L = messages.by_name(messages.LINK)
assert len(FIELDS) <= ARRAY_LEN

# MAVLink codes: a member's index in its enumeration's declaration order
STATE_CODES = codes(RuntimeState)
LAW_CODES = codes(GuidanceLaw)
LOOP_MODE_CODES = codes(LoopMode)


def _elements(field: messages.MessageField, values) -> dict[str, float]:
    """A field's floats by their wire names (a scalar: one, an array: one per element)."""
    if field.kind != "numbers":
        return {field.wire[0]: values}
    return dict(zip(field.wire, values, strict=True))


def loop_values(tel: ControlTelemetry) -> dict[str, float]:
    """The fields one control tick fills (eq. numbers in FIELDS)."""
    cap = tel.speed_cap_m_s  # no limit (inf) is sent as NaN: does not exist
    vals = {
        **_elements(_C["mode"], LOOP_MODE_CODES.index(tel.mode.value)),
        **_elements(_C["los_elev_rad"], tel.los_elev_rad),
        **_elements(_C["los_azim_rad"], tel.los_azim_rad),
        **_elements(_C["vel_elev_rad"], tel.vel_elev_rad),
        **_elements(_C["vel_azim_rad"], tel.vel_azim_rad),
        **_elements(_C["accel_desired_m_s2"], tel.accel_desired_enu_m_s2),
        **_elements(_C["accel_normal_desired_m_s2"], tel.accel_normal_desired_m_s2),
        **_elements(_C["body_rates_cmd_rad_s"], tel.command.body_rates_flu_rad_s),
        **_elements(_C["thrust_cmd"], tel.command.thrust_normalised),
        **_elements(_C["yaw_rate_cmd_rad_s"], tel.yaw_rate_cmd_rad_s),
        **_elements(_D["time_since_detection_s"], min(tel.dkf_time_since_detection_s, 1e6)),
        **_elements(_D["lost"], float(tel.dkf_lost)),
        **_elements(_C["speed_cap_m_s"], cap if math.isfinite(cap) else math.nan),
    }
    if tel.self_cal is not None:
        vals.update(_elements(_D["target_diameter_m"], tel.self_cal.target_diameter_m))
        vals.update(_elements(_D["camera_offset_s"], tel.self_cal.camera_offset_s))
    if tel.e_est_px is not None:
        vals.update(_elements(_C["e_px"], tel.e_est_px))
        vals.update(_elements(_C["e_rate_px_s"], tel.e_rate_est_px_s))
    return vals


def dkf_values(state_px, cov_diag) -> dict[str, float]:
    """The DKF state (e_x, e_y, r_x, r_y) and its covariance diagonal, beyond the estimate
    ``loop_values`` sends (none before the filter starts)."""
    if state_px is None:
        return {}
    vals = _elements(_D["state"], state_px)
    if cov_diag is not None:
        vals.update(_elements(_D["cov_diag"], cov_diag))
    for k in _C["e_px"].wire:  # the estimate is the control tick's (loop_values)
        del vals[k]
    return vals


def detection_values(det: Detection | None, camera: CameraModel) -> dict[str, float]:
    """The latest detection's image error and capture time (none: no fields)."""
    if det is None:
        return {}
    e = camera.error_px(*det.center_px)
    return {
        **_elements(_C["e_raw_px"], e),
        **_elements(_C["raw_capture_t_s"], det.capture_time_s),
    }


def pose_values(pos_enu_m, vel_enu_m_s, q_wxyz) -> dict[str, float]:
    """The vehicle state the tick used (ENU, FLU -> ENU quaternion); None: not known yet."""
    vals: dict[str, float] = {}
    if pos_enu_m is not None:
        vals.update(_elements(_L["pos_m"], pos_enu_m))
        vals.update(_elements(_C["vel_m_s"], vel_enu_m_s))
    if q_wxyz is not None:
        vals.update(_elements(_L["q_wxyz"], q_wxyz))
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
