"""Live mode's frames: the onboard component's telemetry (one ``DEBUG_FLOAT_ARRAY``, layout in
:mod:`onboard.link.telemetry`, unpacked to a name -> value dict) and the poses the ground
link reports, as a :class:`~groundstation.frames.Frame`. Pure: the live session owns the link.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.camera_model import CameraModel
from onboard.datatypes import ControlTelemetry, Detection, LoopMode, RateThrustCommand
from onboard.gains import Gains
from onboard.link import telemetry as tm

from ..frames import Frame, SortieEvent, Vec3

Values = dict[str, float | None]


def _num(x: float | None, missing: float = math.nan) -> float:
    return missing if x is None else float(x)


def _pair(t: Values, a: str, b: str) -> tuple[float, float] | None:
    return None if t.get(a) is None or t.get(b) is None else (t[a], t[b])


def loop_mode(t: Values) -> LoopMode:
    return LoopMode(tm.LOOP_MODE_CODES[int(t.get("loop_mode") or 0)])


def telemetry_from_values(t: Values, law: str) -> ControlTelemetry:
    """The loop's telemetry as the onboard component sent it (NaN fields: missing)."""
    t_s = _num(t.get("t_s"), 0.0)
    return ControlTelemetry(
        time_s=t_s,
        mode=loop_mode(t),
        law=law,
        e_est_px=_pair(t, "e_est_u_px", "e_est_v_px"),
        e_rate_est_px_s=_pair(t, "e_rate_u_px_s", "e_rate_v_px_s"),
        los_elev_rad=_num(t.get("los_elev_rad")),
        los_azim_rad=_num(t.get("los_azim_rad")),
        vel_elev_rad=_num(t.get("vel_elev_rad")),
        vel_azim_rad=_num(t.get("vel_azim_rad")),
        accel_desired_enu_m_s2=np.array(
            [_num(t.get(f"acc_des_{c}_m_s2"), 0.0) for c in ("e", "n", "u")]
        ),
        accel_normal_desired_m_s2=_num(t.get("acc_normal_des_m_s2"), 0.0),
        yaw_rate_cmd_rad_s=_num(t.get("yaw_rate_cmd_rad_s"), 0.0),
        command=RateThrustCommand(
            t_s,
            np.array([_num(t.get(f"rate_cmd_{c}_rad_s"), 0.0) for c in "xyz"]),
            _num(t.get("thrust_cmd"), 0.0),
        ),
        dkf_time_since_detection_s=_num(t.get("dkf_since_det_s"), math.inf),
        dkf_lost=bool(t.get("dkf_lost")),
        guard_tripped=False,
    )


def detection_from_values(t: Values, camera: CameraModel) -> Detection | None:
    """The latest detection the loop received (its centre and capture time; the telemetry
    carries no box, so a 10 px one is drawn)."""
    raw = _pair(t, "e_raw_u_px", "e_raw_v_px")
    if raw is None:
        return None
    u, v = camera.cu_px + raw[0], camera.cv_px + raw[1]
    return Detection(_num(t.get("raw_capture_t_s")), (u, v), (u - 5, v - 5, 10, 10), 100.0)


def pose_from_values(t: Values) -> tuple[Vec3 | None, Vec3 | None, tuple | None]:
    """(position, velocity, attitude wxyz) the control tick used, each None if not sent."""
    p = tuple(t.get(k) for k in ("pos_e_m", "pos_n_m", "pos_u_m"))
    v = tuple(t.get(k) for k in ("vel_e_m_s", "vel_n_m_s", "vel_u_m_s"))
    q = tuple(t.get(k) for k in ("q_w", "q_x", "q_y", "q_z"))
    return (
        None if None in p else p,
        None if None in v else v,
        None if None in q else q,
    )


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
    e, r = tel.e_est_px, _pair(t, "dkf_r_u_px_s", "dkf_r_v_px_s")
    cov = tuple(t.get(k) for k in tm.FIELD_NAMES_DKF_COV)
    return Frame(
        time_s=tel.time_s,
        vehicle_p_enu_m=tuple(vehicle_p),
        vehicle_q_wxyz=tuple(vehicle_q),
        vehicle_v_enu_m_s=tuple(vehicle_v),
        target_p_enu_m=None if target_p is None else tuple(target_p),
        telemetry=tel,
        normal_accel_m_s2=normal_accel_m_s2,
        detection=detection_from_values(t, camera),
        dkf_state_px=None if e is None or r is None else (e[0], e[1], r[0], r[1]),
        dkf_cov_diag=None if None in cov else cov,
        acquired=acquired or tel.mode is LoopMode.TRACKING,
        gains=gains,
        guard_trips=int(t.get("guard_trips") or 0),
        events=events,
    )
