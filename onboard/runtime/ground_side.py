"""The ground's side of ``onboard run``: parameters (PARAM_*), start/abort commands
(COMMAND_LONG, signed when a key is set), the parameter files over MAVLink FTP, the flight
controller's messages forwarded at a limited rate, events as STATUSTEXT and the loop's
telemetry (DEBUG_FLOAT_ARRAY, :mod:`onboard.link.telemetry`).

A mixin of :class:`~onboard.runtime.runner.OnboardRuntime`, run on its control thread.
"""

from __future__ import annotations

from ..link import ftp
from ..link import telemetry as tm
from ..link.params import PARAM_ID_INDEX, PARAM_INDEX, PARAM_NAMES, PARAM_SPECS
from ..link.px4 import (
    CMD_ABORT,
    CMD_START,
    ONBOARD_COMPONENT_ID,
    VEHICLE_SYSTEM_ID,
    mavlink,
    param_id_str,
    real32,
)
from .timing import jitter_p99_ms, rate_hz

TELEMETRY_EVERY = 4  # ticks: 50 Hz at 200 Hz
DKF_FROM_LOOP = object()  # _telemetry: the sender reads the filter's state after the tick
FORWARD_HZ = 25.0  # flight-controller pose passed through to the ground
SEVERITY = {
    "critical": mavlink.MAV_SEVERITY_CRITICAL,
    "error": mavlink.MAV_SEVERITY_ERROR,
    "warning": mavlink.MAV_SEVERITY_WARNING,
    "info": mavlink.MAV_SEVERITY_INFO,
}


class GroundSide:
    """The ground link's handlers and outputs (mixed into the runtime)."""

    # ------------------------------------------------------------------ events
    def _event(self, severity: str, text: str) -> None:
        self._events.append((severity, text))  # sent by the control thread

    def _flush_events(self) -> None:
        while self._events:
            severity, text = self._events.popleft()
            now = self.clock.now()
            self.log(f"[{now:8.3f}] {severity.upper()}: {text}")
            if self.foxglove is not None:
                self.foxglove.event(now, severity, text)
            if self.gcs is not None:
                self.gcs.statustext(SEVERITY.get(severity, mavlink.MAV_SEVERITY_INFO), text)

    def _forward(self, msg, now: float, always: bool = False) -> None:
        """Pass a flight-controller (or target) message through to the ground."""
        if self.gcs is None:
            return
        key = (msg.get_srcSystem(), msg.get_type())
        if not always and now - self._last_forward.get(key, -1e9) < 1.0 / FORWARD_HZ:
            return
        self._last_forward[key] = now
        self.gcs.send_frame(msg.get_msgbuf())

    def _take_gcs(self, msg, _now: float) -> None:
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
            ftp.serve(self.ftp, self.gcs, msg, VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID)

    def _for_us(self, msg) -> bool:
        return msg.target_system == VEHICLE_SYSTEM_ID and msg.target_component in (
            ONBOARD_COMPONENT_ID,
            0,
        )

    def _send_param(self, idx: int) -> None:
        spec = PARAM_SPECS[idx]
        self.gcs.send(
            self.gcs.mav.param_value_encode(
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
            self._event("warning", f"PARAM_SET {param_id[:24]}: unknown parameter")
            return
        ok, why = self.params.set(name, value, flying=self.sm.flying)
        if ok:
            self._event("info", f"param {param_id} = {self.params.get(name):g}")
            if self.loop is not None:
                self.loop.set_gains(self.params.gains)
                self.loop.dkf.config = self.params.runtime.dkf_config()
            rt = self.params.runtime
            self.sm.done_size_frac, self.sm.hold_speed_m_s = rt.DONE_SIZE, rt.HOLD_SPEED
            if name.startswith("CAM_") or name in ("HOVER_THR", "LAW"):
                self.loop = None  # rebuilt with the new camera, airframe or law
            if why:
                self._event("error", why)
        else:
            self._event("warning", f"PARAM_SET refused: {why}"[:50])
        self._send_param(PARAM_INDEX[name])  # the value in force, changed or not

    def _command(self, msg) -> None:
        cmd = msg.command
        if cmd == CMD_START:
            if self.loop is None:
                ok, why = False, "start refused: camera not ready"
            else:
                ok, why = self.sm.command_start()
        elif cmd == CMD_ABORT:
            ok, why = self.sm.command_abort()
        else:
            self._ack(msg, mavlink.MAV_RESULT_UNSUPPORTED)
            return
        self._event("info" if ok else "warning", why)
        self._ack(msg, mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_DENIED)

    def _ack(self, msg, result: int) -> None:
        """COMMAND_ACK addressed to the sender of the command."""
        self.gcs.send(
            self.gcs.mav.command_ack_encode(
                msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            )
        )

    def _telemetry(self, now: float, tel, dkf=DKF_FROM_LOOP) -> None:
        """``dkf``: the filter's ``state_vector()`` at this tick (None before it starts), or
        ``DKF_FROM_LOOP``: the sender takes it from the loop under its lock, right after the
        tick (the filter's covariance is propagated lazily, and that is the dearest part of a
        telemetry tick; a detection fused in between is then in these fields already)."""
        if self.gcs is not None:
            self.sender.submit(self._send_telemetry, self._telemetry_snapshot(now, tel, dkf))

    def _telemetry_snapshot(self, now: float, tel, dkf) -> tuple:
        """What the telemetry of this tick says, taken on the control thread: numbers and
        references to values that are replaced, never changed in place (the encoding is
        :meth:`_send_telemetry`'s, off the tick)."""
        loop, f, timing = self.loop, self.fcs, self.timing
        latency = timing.latency_total_s[-1] if timing.latency_total_s else None
        return (
            now, self.sm.state, timing.recent_periods(), timing.overruns, self.params.version,
            self.params.runtime.law, self.camera.frames, self.camera.detections,
            self.commands_sent, self.target_size_frac, latency,
            loop, None if loop is None else loop.guard_trips,
            self._last_det, dkf, tel, f.pos_enu_m, f.vel_enu_m_s, f.q_wxyz,
        )  # fmt: skip

    def _send_telemetry(self, snapshot: tuple) -> None:
        """One ``DEBUG_FLOAT_ARRAY`` from a :meth:`_telemetry_snapshot`."""
        (now, state, periods, overruns, version, law, frames, detections, commands, size,
         latency, loop, guard_trips, det, dkf, tel, pos, vel, q) = snapshot  # fmt: skip
        if dkf is DKF_FROM_LOOP:
            dkf = None
            if loop is not None:
                with self._loop_lock:
                    dkf = loop.dkf.state_vector()
        vals: dict[str, float | None] = {
            "t_s": now,
            "state": tm.STATE_CODES.index(state.value),
            "loop_rate_hz": rate_hz(periods),
            "loop_jitter_p99_ms": jitter_p99_ms(periods, self.period_s),
            "overruns": overruns,
            "params_version": version,
            "law": tm.LAW_CODES.index(law),
            "frames": frames,
            "detections": detections,
            "commands_sent": commands,
            "target_size_frac": size,
        }
        if latency is not None:
            vals["latency_ms"] = 1000.0 * latency
        if loop is not None:
            cam = loop.camera
            vals.update(
                image_w_px=cam.width_px,
                image_h_px=cam.height_px,
                f_px=cam.f_px,
                guard_trips=guard_trips,
            )
            vals.update(tm.detection_values(det, cam))
            if dkf is not None:
                vals.update(tm.dkf_values(dkf[0], dkf[1]))
        if tel is not None:
            vals.update(tm.loop_values(tel))
        vals.update(tm.pose_values(pos, vel, q))
        self.gcs.send(
            self.gcs.mav.debug_float_array_encode(
                int(now * 1e6), tm.ARRAY_NAME.encode(), tm.ARRAY_ID, tm.pack(vals)
            )
        )
