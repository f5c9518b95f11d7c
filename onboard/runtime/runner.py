"""``onboard run``: the interception loop on the vehicle. The control thread ticks at a fixed
rate (default 200 Hz); each tick reads what the flight controller and the ground sent, feeds
the camera thread's detections to the loop, steps the offboard state machine, sends the
command to PX4 and, every few ticks, telemetry to the ground.

All MAVLink goes through :mod:`onboard.link.px4`; the maths stays in :mod:`onboard.loop`.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera_model import CameraModel
from ..datatypes import GRAVITY_M_S2, GyroSample, LoopMode, VehicleParams, VehicleState
from ..estimation.dkf import DkfConfig
from ..link import ftp
from ..link import telemetry as tm
from ..link.param_meta import FILE_NAMES, component_files
from ..link.params import PARAM_ID_INDEX, PARAM_INDEX, PARAM_NAMES, PARAM_SPECS, ParamTable
from ..link.px4 import (
    AUTOPILOT_COMPONENT_ID,
    CMD_ABORT,
    CMD_START,
    MODE_HOLD,
    MODE_OFFBOARD,
    ONBOARD_COMPONENT_ID,
    PX4_MAIN_AUTO,
    PX4_MAIN_OFFBOARD,
    PX4_SUB_AUTO_LOITER,
    TARGET_SYSTEM_ID,
    VEHICLE_SYSTEM_ID,
    MavLink,
    TlogWriter,
    all_finite,
    flu_to_frd,
    frd_to_flu,
    mavlink,
    ned_to_enu,
    param_id_str,
    quat_ned_frd_to_enu_flu,
    real32,
)
from ..link.timesync import TimesyncEstimator, on_timesync, send_request
from ..loop import InterceptionLoop
from ..perception.detector import RedBalloonDetector
from .camera import CameraThread, Clock, open_source
from .px4_params import PX4_PARAMS_READ, check
from .state_machine import Inputs, OffboardStateMachine, Output, State
from .timing import LoopTiming
from .video import Overlay, VideoConfig, overlay_of, runtime_streamer

TELEMETRY_EVERY = 4  # ticks: 50 Hz at 200 Hz
TIMESYNC_EVERY_S = 0.1  # TIMESYNC requests to PX4 at 10 Hz
FORWARD_HZ = 25.0  # flight-controller pose passed through to the ground
MAX_RATE_RAD_S = 20.0
STREAM_RATES_HZ = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 200.0,
    mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: 200.0,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 100.0,
}
SEVERITY = {
    "critical": mavlink.MAV_SEVERITY_CRITICAL,
    "error": mavlink.MAV_SEVERITY_ERROR,
    "warning": mavlink.MAV_SEVERITY_WARNING,
    "info": mavlink.MAV_SEVERITY_INFO,
}


@dataclass
class RuntimeConfig:
    fc_url: str
    camera: str
    gcs_url: str | None = None
    params_path: Path | None = None
    control_rate_hz: float = 200.0
    signing_key: bytes | None = None
    auto_start: bool = False  # SITL only: start as soon as the target is in view
    stats_path: Path | None = None  # timing figures written here at exit (benchmarks)
    log_dir: Path | None = None  # every MAVLink frame in and out, as a .tlog
    video: VideoConfig | None = None  # the camera as H.264/RTP (onboard run --video)


@dataclass
class FcState:
    heartbeat_rx_s: float | None = None
    last_rx_s: float | None = None
    armed: bool = False
    custom_mode: int = 0
    pos_enu_m: np.ndarray | None = None
    vel_enu_m_s: np.ndarray | None = None
    q_wxyz: np.ndarray | None = None
    rates_flu_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def offboard(self) -> bool:
        return ((self.custom_mode >> 16) & 0xFF) == PX4_MAIN_OFFBOARD


class OnboardRuntime:
    def __init__(self, config: RuntimeConfig, log: Callable[[str], None] | None = None) -> None:
        self.config = config
        self.log = log or (lambda s: print(s, flush=True))
        self.clock = Clock()
        self.params = ParamTable(config.params_path)
        self.ftp = ftp.FtpServer(component_files(self.params.get), FILE_NAMES)
        self.timesync = TimesyncEstimator()  # PX4's boot clock -> ours
        self._next_timesync_s = 0.0
        self.px4_params: dict[str, float] = {}  # what PX4 said (px4_params.PX4_PARAMS_READ)
        self.fc = MavLink(config.fc_url, VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID)
        self.gcs = (
            MavLink(
                config.gcs_url,
                VEHICLE_SYSTEM_ID,
                ONBOARD_COMPONENT_ID,
                config.signing_key,
                unsigned_ok=(mavlink.MAVLINK_MSG_ID_HEARTBEAT,),
            )
            if config.gcs_url
            else None
        )
        self.tlog = None
        if config.log_dir is not None:
            config.log_dir.mkdir(parents=True, exist_ok=True)
            stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
            path = config.log_dir / f"{stamp}_onboard.tlog"
            n = 1
            while path.exists():
                n += 1
                path = config.log_dir / f"{stamp}_onboard_{n}.tlog"
            self.tlog = TlogWriter(path)
            self.fc.tlog = self.tlog
            if self.gcs is not None:
                self.gcs.tlog = self.tlog
        rt = self.params.runtime
        self.sm = OffboardStateMachine(rt.DONE_SIZE, rt.HOLD_SPEED, config.auto_start)
        self.fcs = FcState()
        self.loop: InterceptionLoop | None = None
        self.period_s = 1.0 / config.control_rate_hz
        self.camera = CameraThread(
            lambda: open_source(config.camera, self.clock, self.params.runtime.CAM_LAT_S),
            RedBalloonDetector(),
            self.clock,
            on_error=lambda msg: self._event("warning", f"camera: {msg}"),
        )
        self._stop = threading.Event()
        self._tick_n = 0
        self._events: deque[tuple[str, str]] = deque()
        self._last_event = deque(maxlen=1)
        self.commands_sent = 0
        self._last_overrun_report = -1e9
        # ten minutes of figures, not the whole day
        self.timing = LoopTiming(self.period_s, keep=int(600 * config.control_rate_hz))
        self._pending_latency: list[tuple[float, float]] = []
        self._last_det = None
        self._last_forward: dict[tuple[int, str], float] = {}
        self._last_hb_sent = -1e9
        self._mode_requested = 0
        self.target_size_frac = 0.0
        for note in self.params.notes:
            self._event("warning", note)
        self.video_overlay = Overlay()
        self.video = None if config.video is None else runtime_streamer(self)

    # ------------------------------------------------------------------ events
    def _event(self, severity: str, text: str) -> None:
        self._events.append((severity, text))  # sent by the control thread

    def _flush_events(self) -> None:
        while self._events:
            severity, text = self._events.popleft()
            self.log(f"[{self.clock.now():8.3f}] {severity.upper()}: {text}")
            if self.gcs is not None:
                self.gcs.statustext(SEVERITY.get(severity, mavlink.MAV_SEVERITY_INFO), text)

    # ------------------------------------------------------------------ the loop object
    def _build_loop(self, width: int, height: int) -> None:
        rt = self.params.runtime
        cam = CameraModel(width, height, rt.CAM_HFOV_DEG, rt.CAM_PITCH_DEG, rt.CAM_ROLL_DEG)
        vehicle = VehicleParams(mass_kg=1.0, max_thrust_n=GRAVITY_M_S2 / rt.HOVER_THR)
        self.loop = InterceptionLoop(
            cam,
            vehicle,
            self.params.gains,
            law=rt.law,
            control_rate_hz=self.config.control_rate_hz,
            dkf_config=DkfConfig(lost_timeout_s=rt.TGT_LOST_S),
        )
        self._event("info", f"camera {width}x{height}, law {rt.law}: loop ready")

    # ------------------------------------------------------------------ inputs
    def _take_fc(self, msg, now: float) -> None:
        f = self.fcs
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        kind = msg.get_type()
        if src_sys == TARGET_SYSTEM_ID:
            if kind in ("LOCAL_POSITION_NED", "HEARTBEAT"):
                self._forward(msg, now)
            return
        if src_sys != VEHICLE_SYSTEM_ID or src_comp != AUTOPILOT_COMPONENT_ID:
            return
        f.last_rx_s = now
        if kind == "HEARTBEAT":
            f.heartbeat_rx_s = now
            f.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            f.custom_mode = int(msg.custom_mode)
            self._forward(msg, now, always=True)
        elif kind == "ATTITUDE_QUATERNION":
            q = (msg.q1, msg.q2, msg.q3, msg.q4)
            rates = (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
            if all_finite(q + rates) and abs(math.fsum(c * c for c in q) - 1.0) < 0.1:
                f.q_wxyz = quat_ned_frd_to_enu_flu(q)
                f.rates_flu_rad_s = frd_to_flu(rates)
                self._forward(msg, now)
        elif kind == "LOCAL_POSITION_NED":
            p, v = (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz)
            if all_finite(p + v):
                f.pos_enu_m, f.vel_enu_m_s = ned_to_enu(p), ned_to_enu(v)
                self._forward(msg, now)
        elif kind == "HIGHRES_IMU":
            g = (msg.xgyro, msg.ygyro, msg.zgyro)
            if all_finite(g) and self.loop is not None:
                self.loop.on_gyro(
                    GyroSample(self._fc_time(msg.time_usec * 1e-6, now), frd_to_flu(g))
                )
        elif kind == "TIMESYNC":
            on_timesync(self.fc, self.timesync, msg, self._arrival_s(msg, now))
        elif kind == "PARAM_VALUE" and param_id_str(msg.param_id) in PX4_PARAMS_READ:
            name, g = param_id_str(msg.param_id), self.params.gains
            said = check(name, float(msg.param_value), self.params.runtime.HOVER_THR, g.v_max)
            self.px4_params[name] = float(msg.param_value)
            if said is not None:
                self._event(*said)
        elif kind == "STATUSTEXT":
            self._forward(msg, now, always=True)
        elif kind == "COMMAND_ACK":
            if msg.target_component not in (0, ONBOARD_COMPONENT_ID):
                return  # an answer to somebody else on the link
            if msg.command == mavlink.MAV_CMD_DO_SET_MODE and self._mode_requested:
                if msg.result == mavlink.MAV_RESULT_ACCEPTED:
                    f.custom_mode = self._mode_requested  # the next heartbeat confirms
                self._mode_requested = 0
            if msg.result != mavlink.MAV_RESULT_ACCEPTED:
                self._event("warning", f"PX4 refused command {msg.command} ({msg.result})")

    def _arrival_s(self, msg, now: float) -> float:
        """When a frame reached us (the kernel's UDP timestamp when there is one)."""
        rx = getattr(msg, "rx_monotonic_s", None)
        return now if rx is None else self.clock.now() - (time.monotonic() - rx)

    def _fc_time(self, t_fc_s: float, now: float) -> float:
        """A flight-controller sample time in our clock (TIMESYNC), else its arrival."""
        t = self.timesync.to_companion(t_fc_s)
        return now if t is None or not now - 0.5 <= t <= now + 0.002 else min(t, now)

    def _forward(self, msg, now: float, always: bool = False) -> None:
        """Pass a flight-controller (or target) message through to the ground."""
        if self.gcs is None:
            return
        key = (msg.get_srcSystem(), msg.get_type())
        if not always and now - self._last_forward.get(key, -1e9) < 1.0 / FORWARD_HZ:
            return
        self._last_forward[key] = now
        try:
            self.gcs.conn.write(msg.get_msgbuf())
        except Exception:
            self.gcs.send_errors += 1

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
                self.loop.dkf.config = DkfConfig(lost_timeout_s=self.params.runtime.TGT_LOST_S)
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

    # ------------------------------------------------------------------ outputs
    def _send_command(self, rates_flu: np.ndarray, thrust: float, now: float) -> bool:
        rates = flu_to_frd(rates_flu)
        ok = (
            all_finite((*tuple(rates), thrust))
            and 0.0 <= thrust <= 1.0
            and all(abs(r) <= MAX_RATE_RAD_S for r in rates)
        )
        if not ok:  # the last line of defence: nothing non-finite or wild reaches PX4
            self._event("error", "output guard: bad command replaced by hover")
            rates = np.zeros(3)
            thrust = self.params.runtime.HOVER_THR
        sent = self.fc.send(
            self.fc.mav.set_attitude_target_encode(
                int(now * 1000) & 0xFFFFFFFF,
                VEHICLE_SYSTEM_ID,
                AUTOPILOT_COMPONENT_ID,
                mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE,
                (1.0, 0.0, 0.0, 0.0),
                float(rates[0]),
                float(rates[1]),
                float(rates[2]),
                float(thrust),
            )
        )
        if sent:
            self.commands_sent += 1
        return sent

    def _request_streams(self) -> None:
        """Ask PX4 for the state at the rates the loop needs (MAV_CMD_SET_MESSAGE_INTERVAL)."""
        for msg_id, hz in STREAM_RATES_HZ.items():
            self._fc_command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)
        for name in PX4_PARAMS_READ:  # and the parameters we depend on (px4_params.py)
            self.fc.send(self.fc.mav.param_request_read_encode(VEHICLE_SYSTEM_ID,
                         AUTOPILOT_COMPONENT_ID, name.encode(), -1))  # fmt: skip

    def _fc_command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.fc.send(
            self.fc.mav.command_long_encode(
                VEHICLE_SYSTEM_ID, AUTOPILOT_COMPONENT_ID, command, 0, *p
            )
        )

    def _telemetry(self, now: float, tel) -> None:
        if self.gcs is None:
            return
        loop = self.loop
        f = self.fcs
        vals: dict[str, float | None] = {
            "t_s": now,
            "state": tm.STATE_CODES.index(self.sm.state.value),
            "loop_rate_hz": self.loop_rate_hz(),
            "loop_jitter_p99_ms": self.jitter_p99_ms(),
            "overruns": self.overruns,
            "params_version": self.params.version,
            "law": tm.LAW_CODES.index(self.params.runtime.law),
            "frames": self.camera.frames,
            "detections": self.camera.detections,
            "commands_sent": self.commands_sent,
            "target_size_frac": self.target_size_frac,
        }
        if self.timing.latency_total_s:
            vals["latency_ms"] = 1000.0 * self.timing.latency_total_s[-1]
        if loop is not None:
            cam = loop.camera
            vals.update(
                image_w_px=cam.width_px,
                image_h_px=cam.height_px,
                f_px=cam.f_px,
                guard_trips=loop.guard_trips,
            )
            vals.update(tm.detection_values(self._last_det, cam))
            state = loop.dkf.state_vector()
            if state is not None:
                vals.update(tm.dkf_values(state[0], state[1]))
        if tel is not None:
            vals.update(tm.loop_values(tel))
        vals.update(tm.pose_values(f.pos_enu_m, f.vel_enu_m_s, f.q_wxyz))
        self.gcs.send(
            self.gcs.mav.debug_float_array_encode(
                int(now * 1e6), tm.ARRAY_NAME.encode(), tm.ARRAY_ID, tm.pack(vals)
            )
        )

    def _heartbeats(self, now: float) -> None:
        if now - self._last_hb_sent < 1.0:
            return
        self._last_hb_sent = now
        status = mavlink.MAV_STATE_ACTIVE if self.sm.flying else mavlink.MAV_STATE_STANDBY
        for link in (self.fc, self.gcs):
            if link is not None:
                link.heartbeat(
                    mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                    mavlink.MAV_AUTOPILOT_INVALID,
                    0,
                    tm.STATE_CODES.index(self.sm.state.value),
                    status,
                )

    # ------------------------------------------------------------------ timing figures
    @property
    def overruns(self) -> int:
        return self.timing.overruns

    def loop_rate_hz(self) -> float:
        return self.timing.loop_rate_hz()

    def jitter_p99_ms(self) -> float:
        return self.timing.jitter_p99_ms()

    def stats(self) -> dict:
        return {
            **self.timing.figures(),
            "frames": self.camera.frames,
            "commands_sent": self.commands_sent,
            "bad_frames_fc": self.fc.bad_frames,
            "bad_frames_gcs": None if self.gcs is None else self.gcs.bad_frames,
            "state": self.sm.state.value,
            "reason": self.sm.reason,
            "clock_zero_monotonic_s": time.monotonic() - self.clock.now(),
            "timesync_offset_s": self.timesync.offset_now_s,
            "timesync_skew_ppm": 1e6 * self.timesync.skew,
            "timesync_min_rtt_ms": None
            if self.timesync.min_rtt_s is None
            else 1000 * self.timesync.min_rtt_s,
            "timesync_accepted": self.timesync.accepted,
        }

    # ------------------------------------------------------------------ the tick
    def tick(self) -> None:
        now = self.clock.now()
        for link, take in ((self.fc, self._take_fc), (self.gcs, self._take_gcs)):
            if link is None:
                continue
            for msg in link.poll():
                try:
                    take(msg, now)
                except (ValueError, TypeError, OverflowError, KeyError, IndexError) as exc:
                    # a well-formed frame with nonsense inside (NaN where an integer belongs)
                    link.bad_frames += 1
                    self._event("warning", f"{msg.get_type()} ignored: {type(exc).__name__}")
        if self.loop is None and self.camera.last_frame is not None:
            h, w = self.camera.last_frame.image.shape[:2]
            self._build_loop(w, h)
        loop = self.loop
        for ev in self.camera.drain():
            if loop is None:
                continue
            if ev.image_size != (loop.camera.width_px, loop.camera.height_px):
                self._event("error", f"camera size changed to {ev.image_size}: frame ignored")
                continue
            if ev.detection is not None:
                loop.on_detection(ev.detection)
                self._last_det = ev.detection
                bw = ev.detection.bbox_px[2]
                self.target_size_frac = bw / loop.camera.width_px
                self._pending_latency.append((ev.capture_time_s, ev.received_time_s))
        f = self.fcs
        tel = None
        if loop is not None and f.pos_enu_m is not None and f.q_wxyz is not None:
            state = VehicleState(now, f.pos_enu_m, f.vel_enu_m_s, f.q_wxyz, f.rates_flu_rad_s)
            tel = loop.tick(state, brake=self.sm.state is State.BRAKING)
        if self.video is not None:
            self.video_overlay = overlay_of(
                self._last_det, tel and tel.e_est_px, loop and loop.camera, now
            )
        silence = None if f.heartbeat_rx_s is None else now - f.last_rx_s
        tracking = tel is not None and tel.mode is LoopMode.TRACKING
        decision = self.sm.step(
            Inputs(
                now_s=now,
                fc_silence_s=silence,
                armed=f.armed,
                offboard=f.offboard,
                tracking=tracking,
                target_lost=tel is not None and tel.mode is LoopMode.LOST,
                target_size_frac=self.target_size_frac,
                speed_m_s=0.0 if f.vel_enu_m_s is None else float(np.linalg.norm(f.vel_enu_m_s)),
            )
        )
        for ev in decision.events:
            self._event(*ev)
        if decision.request_streams:
            self._request_streams()
        if decision.output is not Output.NONE and tel is not None:
            self._send_command(tel.command.body_rates_flu_rad_s, tel.command.thrust_normalised, now)
            sent_at = self.clock.now()
            if tel.mode is LoopMode.TRACKING and loop.last_fusion:
                for cap, rec in self._pending_latency:
                    self.timing.command_sent(sent_at, cap, rec)
                self._pending_latency.clear()
        if self.sm.state is not State.INTERCEPT or not tracking:
            self._pending_latency.clear()
        if decision.request_arm:
            self._fc_command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        if decision.request_offboard:
            self._mode_requested = MODE_OFFBOARD
            self._fc_command(
                mavlink.MAV_CMD_DO_SET_MODE,
                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                PX4_MAIN_OFFBOARD,
            )
        if decision.request_hold:
            self._mode_requested = MODE_HOLD
            self._fc_command(
                mavlink.MAV_CMD_DO_SET_MODE,
                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                PX4_MAIN_AUTO,
                PX4_SUB_AUTO_LOITER,
            )
        self._heartbeats(now)
        if now >= self._next_timesync_s:
            self._next_timesync_s = now + TIMESYNC_EVERY_S
            send_request(self.fc, self.clock.now())
        if self._tick_n % TELEMETRY_EVERY == 0:
            self._telemetry(now, tel)
        self._flush_events()
        self._tick_n += 1

    # ------------------------------------------------------------------ run
    def stop(self) -> None:
        self._stop.set()

    def run(self, duration_s: float | None = None) -> int:
        sys.setswitchinterval(0.0005)  # let the control thread take the GIL promptly
        self.camera.start()
        if self.video is not None:
            self.video.start()
        self._event("info", f"onboard up: {self.config.control_rate_hz:g} Hz, FC {self.fc.url}")
        period = self.period_s
        next_t = time.perf_counter()
        end = None if duration_s is None else time.perf_counter() + duration_s
        try:
            while not self._stop.is_set():
                start = time.perf_counter()
                self.timing.tick_started(start)
                self.tick()
                work = time.perf_counter() - start
                next_t += period
                now = time.perf_counter()
                overran = self.timing.tick_done(work)
                if overran and now - self._last_overrun_report > 5.0:
                    self._last_overrun_report = now
                    self._event("warning", f"loop overrun: tick took {1000 * work:.1f} ms")
                if now > next_t + period:  # far behind (a stall): do not try to catch up
                    next_t = now
                elif now < next_t:
                    time.sleep(next_t - now)
                if end is not None and now >= end:
                    break
        except KeyboardInterrupt:
            pass
        finally:
            self.camera.stop()
            if self.video is not None:
                self.video.stop()
            if self.camera.is_alive():
                self.camera.join(timeout=2.5)  # a blocked read ends by its own timeout
            self._event("info", f"onboard stopping ({self.sm.state.value})")
            self._flush_events()
            if self.config.stats_path is not None:
                self.config.stats_path.write_text(json.dumps(self.stats(), indent=1))
            self.fc.close()
            if self.gcs is not None:
                self.gcs.close()
            if self.tlog is not None:
                self.tlog.close()
        return 0
