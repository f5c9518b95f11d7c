"""Live mode's frames: the onboard component's telemetry (one ``DEBUG_FLOAT_ARRAY``, layout in
:mod:`onboard.link.telemetry`, unpacked to a name -> value dict) and the poses the ground
link reports, as a :class:`~onboard.frames.Frame`. Pure: the live session owns the link.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.camera_model import CameraModel
from onboard.datatypes import ControlTelemetry, Detection, LoopMode, RateThrustCommand
from onboard.estimation.self_calibration import SelfCalEstimate
from onboard.frames import Frame, SortieEvent, Vec3
from onboard.gains import Gains
from onboard.link import telemetry as tm
from onboard.messages import CONTROL, DKF, LINK, MessageField, by_name

Values = dict[str, float | None]
_C, _D, _L = by_name(CONTROL), by_name(DKF), by_name(LINK)


def _num(x: float | None, missing: float = math.nan) -> float:
    return missing if x is None else float(x)


def _elements(t: Values, field: MessageField, n: int | None = None) -> tuple | None:
    """A field's (first ``n``) floats as sent (its wire names); None if any is missing."""
    vals = tuple(t.get(k) for k in field.wire[:n])
    return None if None in vals else vals


def _one(t: Values, field: MessageField) -> float | None:
    return t.get(field.wire[0])


def loop_mode(t: Values) -> LoopMode:
    return LoopMode(tm.LOOP_MODE_CODES[int(_one(t, _C["mode"]) or 0)])


def telemetry_from_values(t: Values, law: str) -> ControlTelemetry:
    """The loop's telemetry as the onboard component sent it (NaN fields: missing)."""
    t_s = _num(_one(t, _C["t_s"]), 0.0)
    cap = _num(_one(t, _C["speed_cap_m_s"]))
    return ControlTelemetry(
        time_s=t_s,
        mode=loop_mode(t),
        law=law,
        e_est_px=_elements(t, _C["e_px"]),
        e_rate_est_px_s=_elements(t, _C["e_rate_px_s"]),
        los_elev_rad=_num(_one(t, _C["los_elev_rad"])),
        los_azim_rad=_num(_one(t, _C["los_azim_rad"])),
        vel_elev_rad=_num(_one(t, _C["vel_elev_rad"])),
        vel_azim_rad=_num(_one(t, _C["vel_azim_rad"])),
        accel_desired_enu_m_s2=np.array(
            [_num(t.get(k), 0.0) for k in _C["accel_desired_m_s2"].wire]
        ),
        accel_normal_desired_m_s2=_num(_one(t, _C["accel_normal_desired_m_s2"]), 0.0),
        yaw_rate_cmd_rad_s=_num(_one(t, _C["yaw_rate_cmd_rad_s"]), 0.0),
        command=RateThrustCommand(
            t_s,
            np.array([_num(t.get(k), 0.0) for k in _C["body_rates_cmd_rad_s"].wire]),
            _num(_one(t, _C["thrust_cmd"]), 0.0),
        ),
        dkf_time_since_detection_s=_num(_one(t, _D["time_since_detection_s"]), math.inf),
        dkf_lost=bool(_one(t, _D["lost"])),
        guard_tripped=False,
        self_cal=_self_cal(t),
        speed_cap_m_s=cap if math.isfinite(cap) else math.inf,  # NaN on the link: none
    )


def _self_cal(t: Values) -> SelfCalEstimate | None:
    """The in-flight estimates the link carries (their 1 sigma stays onboard: NaN)."""
    d, o = _one(t, _D["target_diameter_m"]), _one(t, _D["camera_offset_s"])
    if d is None or o is None or not (math.isfinite(d) and math.isfinite(o)):
        return None
    return SelfCalEstimate(float(d), math.nan, float(o), math.nan, 0, 0)


def detection_from_values(t: Values, camera: CameraModel) -> Detection | None:
    """The latest detection the loop received (its centre and capture time; the telemetry
    carries no box, so a 10 px one is drawn)."""
    raw = _elements(t, _C["e_raw_px"])
    if raw is None:
        return None
    u, v = camera.cu_px + raw[0], camera.cv_px + raw[1]
    capture_t_s = _num(_one(t, _C["raw_capture_t_s"]))
    return Detection(capture_t_s, (u, v), (u - 5, v - 5, 10, 10), 100.0)


def pose_from_values(t: Values) -> tuple[Vec3 | None, Vec3 | None, tuple | None]:
    """(position, velocity, attitude wxyz) the control tick used, each None if not sent."""
    return _elements(t, _L["pos_m"]), _elements(t, _C["vel_m_s"]), _elements(t, _L["q_wxyz"])


def live_frame(
    t: Values,
    *,
    law: str,
    camera: CameraModel,
    gains: Gains,
    vehicle_p: Vec3,
    vehicle_v: Vec3,
    vehicle_q: tuple[float, float, float, float],
    target_p: Vec3 | None,
    normal_accel_m_s2: float | None,
    acquired: bool,
    events: tuple[SortieEvent, ...] = (),
) -> Frame:
    """One frame from one telemetry message and the latest poses (onboard clock)."""
    tel = telemetry_from_values(t, law)
    state, cov = _elements(t, _D["state"]), _elements(t, _D["cov_diag"])
    return Frame(
        time_s=tel.time_s,
        vehicle_p_enu_m=tuple(vehicle_p),
        vehicle_q_wxyz=tuple(vehicle_q),
        vehicle_v_enu_m_s=tuple(vehicle_v),
        target_p_enu_m=None if target_p is None else tuple(target_p),
        telemetry=tel,
        normal_accel_m_s2=normal_accel_m_s2,
        detection=detection_from_values(t, camera),
        dkf_state_px=state,
        dkf_cov_diag=cov,
        acquired=acquired or tel.mode is LoopMode.TRACKING,
        gains=gains,
        guard_trips=int(_one(t, _L["guard_trips"]) or 0),
        events=events,
    )
