"""The ground's side of ``onboard run``: parameters (PARAM_*), start/abort commands
(COMMAND_LONG, signed when a key is set), the parameter files over MAVLink FTP, the flight
controller's messages forwarded at a limited rate, events as STATUSTEXT and the loop's
telemetry (DEBUG_FLOAT_ARRAY, :mod:`onboard.link.telemetry`)."""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..link import ftp
from ..link import telemetry as tm
from ..link.param_meta import FILE_NAMES, component_files
from ..link.params import PARAM_ID_INDEX, PARAM_INDEX, PARAM_NAMES, PARAM_SPECS, ParamTable
from ..link.px4 import (
    CMD_ABORT,
    CMD_START,
    ONBOARD_COMPONENT_ID,
    VEHICLE_SYSTEM_ID,
    MavLink,
    mavlink,
    param_id_str,
    real32,
)
from .timing import jitter_p99_ms, rate_hz

TELEMETRY_EVERY = 4  # ticks: 50 Hz at 200 Hz
FORWARD_HZ = 25.0  # flight-controller pose passed through to the ground
SEVERITY = {
    "critical": mavlink.MAV_SEVERITY_CRITICAL,
    "error": mavlink.MAV_SEVERITY_ERROR,
    "warning": mavlink.MAV_SEVERITY_WARNING,
    "info": mavlink.MAV_SEVERITY_INFO,
}


class Events:
    """Events (severity, text) queued by any thread, published in order by :meth:`drain`'s
    caller."""

    def __init__(self) -> None:
        self._queue: deque[tuple[str, str]] = deque()

    def add(self, severity: str, text: str) -> None:
        self._queue.append((severity, text))

    def __bool__(self) -> bool:
        return bool(self._queue)

    def drain(self) -> list[tuple[str, str]]:
        out = []
        while self._queue:
            out.append(self._queue.popleft())
        return out


@dataclass(frozen=True)
class TelemetrySnapshot:
    """What one telemetry message says, taken on the control thread: numbers and references
    to values that are replaced, never changed in place (encoded off the tick). ``dkf``: the
    filter's ``state_vector()``, or None to read it from ``loop`` under ``loop_lock`` when
    sending (the covariance is propagated lazily, the dearest part of a telemetry tick)."""

    now_s: float
    state: Any  # the state machine's State
    periods: list
    overruns: int
    params_version: int
    law: str
    frames: int
    detections: int
    commands_sent: int
    target_size_frac: float
    latency_s: float | None
    loop: Any
    guard_trips: int | None
    detection: Any
    dkf: Any
    tel: Any
    pos_enu_m: Any
    vel_enu_m_s: Any
    q_wxyz: Any


class GroundSide:
    """The ground link (None: no ground link; outputs then go nowhere). :meth:`take` each
    message from it; a parameter change is applied to the table here and reported to
    ``on_param_changed(name)``, a start or abort command to ``on_command(command)``, which
    answers (accepted, why)."""

    def __init__(
        self,
        link: MavLink | None,
        params: ParamTable,
        event: Callable[[str, str], None],
        flying: Callable[[], bool],
        on_param_changed: Callable[[str], None],
        on_command: Callable[[int], tuple[bool, str]],
    ) -> None:
        self.link = link
        self.params = params
        self.event = event
        self._flying = flying
        self._on_param_changed = on_param_changed
        self._on_command = on_command
        self.ftp = ftp.FtpServer(component_files(params.get), FILE_NAMES)
        self._last_forward: dict[tuple[int, str], float] = {}

    # ------------------------------------------------------------------ outputs
    def publish(self, severity: str, text: str) -> None:
        if self.link is not None:
            self.link.statustext(SEVERITY.get(severity, mavlink.MAV_SEVERITY_INFO), text)

    def forward(self, msg, now: float, always: bool = False) -> None:
        """Pass a flight-controller (or target) message through to the ground, each kind at
        most at ``FORWARD_HZ`` unless ``always``."""
        if self.link is None:
            return
        key = (msg.get_srcSystem(), msg.get_type())
        if not always and now - self._last_forward.get(key, -1e9) < 1.0 / FORWARD_HZ:
            return
        self._last_forward[key] = now
        self.link.send_frame(msg.get_msgbuf())

    def heartbeat(self, state_code: int, status: int) -> None:
        if self.link is not None:
            self.link.heartbeat(
                mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0,
                state_code, status,
            )  # fmt: skip

    # ------------------------------------------------------------------ inputs
    def take(self, msg, _now: float) -> None:
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST" and self._for_us(msg):
            for i in range(len(PARAM_SPECS)):
                self._send_param(i)
        elif kind == "PARAM_REQUEST_READ" and self._for_us(msg):
            name = param_id_str(msg.param_id)
            idx = PARAM_ID_INDEX.get(name, -1) if msg.param_index < 0 else msg.param_index
            if 0 <= idx < len(PARAM_SPECS):
                self._send_param(idx)
        elif kind == "PARAM_SET" and self._for_us(msg):
            self._param_set(param_id_str(msg.param_id), real32(msg.param_value))
        elif kind == "COMMAND_LONG" and self._for_us(msg):
            self._command(msg)
        elif kind == "FILE_TRANSFER_PROTOCOL":
            ftp.serve(self.ftp, self.link, msg, VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID)

    @staticmethod
    def _for_us(msg) -> bool:
        return msg.target_system == VEHICLE_SYSTEM_ID and msg.target_component in (
            ONBOARD_COMPONENT_ID,
            0,
        )

    def _send_param(self, idx: int) -> None:
        spec = PARAM_SPECS[idx]
        self.link.send(
            self.link.mav.param_value_encode(
                spec.param_id.encode("ascii"),
                self.params.get(spec.name),
                mavlink.MAV_PARAM_TYPE_REAL32,
                len(PARAM_SPECS),
                idx,
            )
        )

    def _param_set(self, param_id: str, value: float) -> None:
        name = PARAM_NAMES.get(param_id)
        if name is None:
            self.event("warning", f"PARAM_SET {param_id[:24]}: unknown parameter")
            return
        ok, why = self.params.set(name, value, flying=self._flying())
        if ok:
            self.event("info", f"param {param_id} = {self.params.get(name):g}")
            self._on_param_changed(name)
            if why:
                self.event("error", why)
        else:
            self.event("warning", f"PARAM_SET refused: {why}"[:50])
        self._send_param(PARAM_INDEX[name])  # the value in force, changed or not

    def _command(self, msg) -> None:
        if msg.command not in (CMD_START, CMD_ABORT):
            self._ack(msg, mavlink.MAV_RESULT_UNSUPPORTED)
            return
        ok, why = self._on_command(msg.command)
        self.event("info" if ok else "warning", why)
        self._ack(msg, mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_DENIED)

    def _ack(self, msg, result: int) -> None:
        """COMMAND_ACK addressed to the sender of the command."""
        self.link.send(
            self.link.mav.command_ack_encode(
                msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            )
        )

    # ------------------------------------------------------------------ telemetry
    def send_telemetry(self, s: TelemetrySnapshot, period_s: float, loop_lock: threading.RLock):
        """One ``DEBUG_FLOAT_ARRAY`` from a snapshot (on the sender thread)."""
        if self.link is None:
            return
        dkf, loop = s.dkf, s.loop
        if dkf is None and loop is not None:
            with loop_lock:
                dkf = loop.dkf.state_vector()
        vals: dict[str, float | None] = {
            "t_s": s.now_s,
            "state": tm.STATE_CODES.index(s.state.value),
            "loop_rate_hz": rate_hz(s.periods),
            "loop_jitter_p99_ms": jitter_p99_ms(s.periods, period_s),
            "overruns": s.overruns,
            "params_version": s.params_version,
            "law": tm.LAW_CODES.index(s.law),
            "frames": s.frames,
            "detections": s.detections,
            "commands_sent": s.commands_sent,
            "target_size_frac": s.target_size_frac,
        }
        if s.latency_s is not None:
            vals["latency_ms"] = 1000.0 * s.latency_s
        if loop is not None:
            cam = loop.camera
            vals.update(
                image_w_px=cam.width_px,
                image_h_px=cam.height_px,
                f_px=cam.f_px,
                guard_trips=s.guard_trips,
            )
            vals.update(tm.detection_values(s.detection, cam))
            if dkf is not None:
                vals.update(tm.dkf_values(dkf[0], dkf[1]))
        if s.tel is not None:
            vals.update(tm.loop_values(s.tel))
        vals.update(tm.pose_values(s.pos_enu_m, s.vel_enu_m_s, s.q_wxyz))
        self.link.send(
            self.link.mav.debug_float_array_encode(
                int(s.now_s * 1e6), tm.ARRAY_NAME.encode(), tm.ARRAY_ID, tm.pack(vals)
            )
        )
