"""The dashboard's view of a frame: one builder for the simulator, live mode and replay, so the
page plots the same quantities, computed the same way, whatever produced the frame."""

from __future__ import annotations

from typing import Any

import numpy as np

from onboard.camera_model import CameraModel
from onboard.control.guidance import normal_component
from onboard.frames import Frame


def frame_snapshot(
    frame: Frame, camera: CameraModel, target_diameter_m: float, t_s: float | None = None
) -> dict[str, Any]:
    """The frame part of the telemetry message the page receives (``t_s``: the time to show,
    if not the frame's own, e.g. a replay's cursor). Velocity normal to the line of sight and
    the raw detection's image error are computed here, from the frame."""
    p, v, tp = frame.vehicle_p_enu_m, frame.vehicle_v_enu_m_s, frame.target_p_enu_m
    tel, det = frame.telemetry, frame.detection
    v_n = None
    if tp is not None and v is not None:
        v_n = normal_component(np.array(v), np.subtract(tp, p))
    return {
        "t": round(frame.time_s if t_s is None else t_s, 4),
        "vehicle": {
            "p": list(p),
            "v": None if v is None else list(v),
            "q": list(frame.vehicle_q_wxyz),
        },
        "target": None if tp is None else {"p": list(tp), "diameter_m": target_diameter_m},
        "range_m": frame.range_m,
        "speed_m_s": frame.speed_m_s,
        "normal_vel_m_s": v_n,
        "normal_accel_m_s2": frame.normal_accel_m_s2,
        "image": {
            "w": camera.width_px,
            "h": camera.height_px,
            "f": camera.f_px,
            "vfov_deg": camera.vfov_deg,
        },
        "e_est_px": None if tel is None or tel.e_est_px is None else list(tel.e_est_px),
        "e_raw_px": None if det is None else list(camera.error_px(*det.center_px)),
        "raw_capture_t": None if det is None else det.capture_time_s,
        "mode": None if tel is None else tel.mode.value,
        "k_a": frame.gains.k_a,
    }
