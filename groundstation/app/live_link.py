"""What the vehicle reports over the ground link, kept up to date from MAVLink: the onboard
component's heartbeat, telemetry (``DEBUG_FLOAT_ARRAY``, layout :mod:`onboard.link.telemetry`),
parameters, acknowledgements and ``STATUSTEXT`` events, the flight controller's pose passed
through, and a cooperative target's own position (system 2). :class:`~.live.LiveSession`
builds on it: what the operator sends, the recording and the page's view."""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from onboard import messages
from onboard.camera_model import CameraModel
from onboard.control.guidance import normal_component
from onboard.gains import GAIN_NAMES, Gains
from onboard.link import telemetry as tm
from onboard.link.params import PARAM_INDEX, PARAM_NAMES
from onboard.link.px4 import (
    AUTOPILOT_COMPONENT_ID,
    GCS_COMPONENT_ID,
    GCS_SYSTEM_ID,
    ONBOARD_COMPONENT_ID,
    TARGET_SYSTEM_ID,
    VEHICLE_SYSTEM_ID,
    MavLink,
    mavlink,
    message_text,
    ned_to_enu,
    param_id_str,
    px4_mode_name,
    quat_ned_frd_to_enu_flu,
    real32,
)

from .live_frames import pose_from_values

LINK_TIMEOUT_S = 2.0


class LinkState:
    """The vehicle as the link last reported it. Messages are taken (:meth:`take`) on the
    link thread under ``self.lock``; its owner hears of telemetry and events through
    ``on_telemetry(values, now)`` and ``on_event(level, text)``."""

    def __init__(
        self,
        url: str,
        signing_key: bytes | None,
        on_telemetry: Callable[[dict[str, float | None], float], None] = lambda t, now: None,
        on_event: Callable[[str, str], None] = lambda level, text: None,
    ) -> None:
        self.on_telemetry, self.on_event = on_telemetry, on_event
        self.link = MavLink(url, GCS_SYSTEM_ID, GCS_COMPONENT_ID, signing_key, unsigned_ok=None)
        self.url = url
        self.signed = signing_key is not None
        self.lock = threading.RLock()
        self.params: dict[str, float] = {}
        self.pending: dict[str, float] = {}  # PARAM_SET sent, PARAM_VALUE not yet back
        self.refused: dict[str, str] = {}
        self.gains = Gains()
        self.initial_gains: Gains | None = None  # the vehicle's, first read in full
        self.gains_applied_time_s: float | None = None
        self.tel: dict[str, float | None] = {}
        self.tel_rx_s: float | None = None
        self.onboard_rx_s: float | None = None
        self.onboard_state = "unknown"
        self.fc_mode = "—"
        self.fc_armed = False
        self.fc_rx_s: float | None = None
        self.vehicle_p: list[float] | None = None
        self.vehicle_v = [0.0, 0.0, 0.0]
        self.vehicle_q = [1.0, 0.0, 0.0, 0.0]
        self.target_p: list[float] | None = None
        self.target_v = [0.0, 0.0, 0.0]
        self.target_rx_s: float | None = None
        self.events: deque[dict[str, Any]] = deque(maxlen=50)
        self.acks: dict[int, tuple[float, int]] = {}
        self.last_ack: dict[str, Any] | None = None
        self.acked = threading.Condition(self.lock)
        self.trail_vehicle: list[list[float]] = []
        self.trail_target: list[list[float]] = []
        self._last_trail = -1.0
        self._prev_vel: tuple[float, list[float]] | None = None
        self.normal_accel_m_s2: float | None = None

    def command(self, command: int, sends: int, timeout_s: float) -> int | None:
        """``COMMAND_LONG`` to the onboard component by the command protocol: sent again, its
        confirmation counting up, when no ``COMMAND_ACK`` came back within ``timeout_s``, at
        most ``sends`` times. The MAV_RESULT, or None when none came back (under the lock; the
        onboard answers a repeated start or abort as it answered the first)."""
        first = time.monotonic()
        for confirmation in range(sends):
            sent_at = time.monotonic()
            self.link.send(
                self.link.mav.command_long_encode(
                    VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID, command, confirmation, 0, 0, 0, 0,
                    0, 0, 0,
                )
            )  # fmt: skip
            while True:
                ack = self.acks.get(command)
                if ack is not None and ack[0] >= first:
                    return ack[1]
                left = sent_at + timeout_s - time.monotonic()
                if left <= 0:
                    break
                self.acked.wait(left)
        return None

    def link_up(self) -> bool:
        return (
            self.onboard_rx_s is not None and time.monotonic() - self.onboard_rx_s < LINK_TIMEOUT_S
        )

    def take(self, m, now: float) -> None:
        kind = m.get_type()
        sys_id, comp = m.get_srcSystem(), m.get_srcComponent()
        if sys_id == TARGET_SYSTEM_ID:
            if kind == "LOCAL_POSITION_NED":
                p, v = ned_to_enu((m.x, m.y, m.z)), ned_to_enu((m.vx, m.vy, m.vz))
                if np.all(np.isfinite(p)) and np.all(np.isfinite(v)):
                    self.target_p, self.target_rx_s = [float(c) for c in p], now
                    self.target_v = [float(c) for c in v]
            return
        if sys_id != VEHICLE_SYSTEM_ID:
            return
        if comp == AUTOPILOT_COMPONENT_ID:
            self.fc_rx_s = now
            if kind == "HEARTBEAT":
                self.fc_mode = px4_mode_name(m.custom_mode)
                self.fc_armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            elif kind == "ATTITUDE_QUATERNION":
                q = quat_ned_frd_to_enu_flu((m.q1, m.q2, m.q3, m.q4))
                if np.all(np.isfinite(q)):
                    self.vehicle_q = [float(c) for c in q]
            elif kind == "LOCAL_POSITION_NED":
                p, v = ned_to_enu((m.x, m.y, m.z)), ned_to_enu((m.vx, m.vy, m.vz))
                if np.all(np.isfinite(p)) and np.all(np.isfinite(v)):
                    self.vehicle_p, self.vehicle_v = [float(c) for c in p], [float(c) for c in v]
            elif kind == "STATUSTEXT":
                self._event(now, "px4", message_text(m), m.severity)
            return
        if comp != ONBOARD_COMPONENT_ID:
            return
        self.onboard_rx_s = now
        if kind == "HEARTBEAT":
            code = int(m.custom_mode)
            self.onboard_state = tm.STATE_CODES[code] if 0 <= code < len(tm.STATE_CODES) else "?"
        elif kind == "DEBUG_FLOAT_ARRAY" and m.array_id == tm.ARRAY_ID:
            self._telemetry(tm.unpack(m.data), now)
        elif kind == "STATUSTEXT":
            self._event(now, "onboard", message_text(m), m.severity)
        elif kind == "PARAM_VALUE":
            name = PARAM_NAMES.get(param_id_str(m.param_id), "")  # MAVLink id -> Python name
            value = real32(m.param_value)
            if name not in PARAM_INDEX or not math.isfinite(value):
                raise ValueError(f"PARAM_VALUE {name!r} = {value}")
            self.params[name] = value
            if name in self.pending:
                want = self.pending.pop(name)
                if math.isclose(want, value, rel_tol=1e-6, abs_tol=1e-6):
                    self.gains_applied_time_s = self.tel.get("t_s")
                else:
                    self.refused[name] = f"{name}: vehicle kept {value:g}"
            if name in GAIN_NAMES:
                with contextlib.suppress(ValueError):
                    self.gains = self.gains.replace(**{name: value})
                if self.initial_gains is None and all(n in self.params for n in GAIN_NAMES):
                    self.initial_gains = self.gains
        elif kind == "COMMAND_ACK" and m.target_component in (0, GCS_COMPONENT_ID):
            self.acks[int(m.command)] = (now, int(m.result))
            self.acked.notify_all()

    def _event(self, now: float, source: str, text: str, severity: int) -> None:
        self.events.append(
            {"t": round(now, 3), "source": source, "text": text, "severity": int(severity)}
        )
        level = (
            "error"
            if severity <= mavlink.MAV_SEVERITY_ERROR
            else ("warning" if severity == mavlink.MAV_SEVERITY_WARNING else "info")
        )
        self.on_event(level, f"{source}: {text}")

    def _telemetry(self, t: dict[str, float | None], now: float) -> None:
        for key, codes in (
            ("state", tm.STATE_CODES),
            ("loop_mode", tm.LOOP_MODE_CODES),
            ("law", tm.LAW_CODES),
        ):
            v = t.get(key)
            if v is not None and not (0 <= v < len(codes) and v == int(v)):
                t[key] = None  # a code we do not know: show nothing rather than fail
        for f in messages.LINK:
            v = None if f.limits is None else t.get(f.wire[0])
            if v is not None and not f.limits[0] <= v <= f.limits[1]:
                t[f.wire[0]] = None
        self.tel, self.tel_rx_s = t, now
        if self.fc_rx_s is None or now - self.fc_rx_s > 1.0:
            # no pass-through from the flight controller: the pose the control tick used
            p, v, q = pose_from_values(t)
            if p is not None and v is not None:
                self.vehicle_p, self.vehicle_v = list(p), list(v)
            if q is not None:
                self.vehicle_q = list(q)
        code = t.get("state")
        if code is not None and 0 <= int(code) < len(tm.STATE_CODES):
            self.onboard_state = tm.STATE_CODES[int(code)]
        v = pose_from_values(t)[1]
        ts = t.get("t_s")
        if v is not None and ts is not None:
            if self._prev_vel is not None and ts > self._prev_vel[0]:
                dt = ts - self._prev_vel[0]
                a = (np.array(v) - np.array(self._prev_vel[1])) / dt
                self.normal_accel_m_s2 = normal_component(a, np.array(v))
            self._prev_vel = (ts, v)
        self.on_telemetry(t, now)
        if self.vehicle_p is not None and ts is not None and ts - self._last_trail >= 0.1:
            self._last_trail = ts
            self.trail_vehicle.append([round(c, 3) for c in self.vehicle_p])
            if self.target_p is not None:
                self.trail_target.append([round(c, 3) for c in self.target_p])

    def camera_model(self) -> CameraModel:
        """The onboard camera: image size and focal length as the telemetry reports them (the
        field of view parameter when it does not), mount angles from the parameters."""
        t = self.tel
        w, h = int(t.get("image_w_px") or 640), int(t.get("image_h_px") or 480)
        f = t.get("f_px")
        hfov = (
            math.degrees(2.0 * math.atan(w / 2.0 / f))
            if f
            else self.params.get("CAM_HFOV_DEG", 90.0)
        )
        return CameraModel(
            w, h, hfov, self.params.get("CAM_PITCH_DEG", 0.0), self.params.get("CAM_ROLL_DEG", 0.0)
        )
