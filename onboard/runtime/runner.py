"""``onboard run``: the interception loop on the vehicle. One control thread ticks at a fixed
rate (default 200 Hz) on absolute deadlines (:mod:`.scheduler`), under SCHED_FIFO with its
memory locked where the system allows it (:mod:`.realtime`). Each tick reads the vehicle state
the receiver threads took from what the flight controller and the ground sent, takes the
camera thread's detections (fused into the filter on the camera thread as they arrive), steps
the offboard state machine (the failsafe wiring), sends the command to PX4 and hands the rest
(telemetry, events, heartbeats, TIMESYNC requests, the state machine's arm, mode and stream
requests) to the sender thread.

The runtime owns its parts: :class:`~.fc_side.FlightControllerSide` (PX4 in and out),
:class:`~.ground_side.GroundSide` (parameters, commands, telemetry, events), the scheduler,
the camera thread (:mod:`.camera`) and the links' threads (:mod:`.receiver`, :mod:`.sender`).
All MAVLink goes through :mod:`onboard.link.px4`; the maths stays in :mod:`onboard.loop`.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..camera_model import CameraModel
from ..datatypes import ControlTelemetry, LoopMode, VehicleParams
from ..link import telemetry as tm
from ..link.fc_state import state_at
from ..link.params import ParamTable
from ..link.px4 import (
    CMD_START,
    MODE_HOLD,
    MODE_OFFBOARD,
    ONBOARD_COMPONENT_ID,
    PX4_MAIN_AUTO,
    PX4_MAIN_OFFBOARD,
    PX4_SUB_AUTO_LOITER,
    VEHICLE_SYSTEM_ID,
    MavLink,
    mavlink,
)
from ..link.tlog import TlogWriter
from ..loop import InterceptionLoop
from ..perception.detector import RedBalloonDetector
from .camera import CameraThread, Clock, open_source
from .faults import WakeDelays
from .fc_side import FlightControllerSide
from .ground_side import TELEMETRY_EVERY, Events, GroundSide, TelemetrySnapshot
from .realtime import DEFAULT_PRIORITY, RealtimeSetup, make_realtime
from .receiver import LinkReceiver
from .scheduler import PeriodicScheduler
from .sender import Sender
from .state_machine import Inputs, OffboardStateMachine, Output, State
from .timing import LoopTiming
from .video import Overlay, VideoConfig, overlay_of, runtime_streamer

# the loop flies without a live track (coast, re-acquisition, search: see onboard/loop.py)
_STALE_MODES = (LoopMode.COAST, LoopMode.REACQUIRE, LoopMode.SEARCH)
TIMESYNC_EVERY_S = 0.1  # TIMESYNC requests to PX4 at 10 Hz
OVERRUN_REPORT_EVERY_S = 5.0


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
    realtime_priority: int | None = DEFAULT_PRIORITY  # the control thread's; None: normal
    lock_memory: bool = True  # mlockall while the loop runs
    cpu: int | None = None  # the control thread's CPU (None: the isolated ones, if any)
    inject_delays_seed: int | None = None  # wake-ups delayed (faults.WakeDelays), seeded
    video: VideoConfig | None = None  # the camera as H.264/RTP (onboard run --video)
    foxglove: tuple[str, int] | None = None  # (host, port): Foxglove live (onboard run --foxglove)


class OnboardRuntime:
    """The vehicle's runtime: the links, the camera thread, the loop and the state machine."""

    def __init__(self, config: RuntimeConfig, log: Callable[[str], None] | None = None) -> None:
        self.config = config
        self.log = log or (lambda s: print(s, flush=True))
        self.clock = Clock()
        self.params = ParamTable(config.params_path)
        self.events = Events()
        rt = self.params.runtime
        self.sm = OffboardStateMachine(rt.DONE_SIZE, rt.HOLD_SPEED, config.auto_start)
        fc_link = MavLink(config.fc_url, VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID)
        gcs_link = None
        if config.gcs_url:
            gcs_link = MavLink(
                config.gcs_url, VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID, config.signing_key,
                unsigned_ok=(mavlink.MAVLINK_MSG_ID_HEARTBEAT,),
            )  # fmt: skip
        self.tlog = None if config.log_dir is None else TlogWriter.new_in(config.log_dir, "onboard")
        for link in (fc_link, gcs_link):
            if link is not None:
                link.tlog = self.tlog
        self.ground = GroundSide(
            gcs_link, self.params, self.events.add, lambda: self.sm.flying,
            self._param_changed, self._command,
        )  # fmt: skip
        self.fc = FlightControllerSide(
            fc_link, self.params, self.clock, self.events.add, self.ground.forward
        )
        self.loop: InterceptionLoop | None = None
        self.period_s = 1.0 / config.control_rate_hz
        seed = config.inject_delays_seed
        self.scheduler = PeriodicScheduler(
            self.period_s, delays=None if seed is None else WakeDelays(seed)
        )
        self.realtime: RealtimeSetup | None = None  # run(): what the system granted
        # started by run(), which takes what the links bring as it arrives; tick() polls without
        self._fc_rx: LinkReceiver | None = None
        self._gcs_rx: LinkReceiver | None = None
        self.sender = Sender(on_error=lambda msg: self.events.add("error", msg))
        self.camera = CameraThread(
            lambda: open_source(config.camera, self.clock, self.params.runtime.CAM_LAT_S),
            RedBalloonDetector(),
            self.clock,
            on_error=lambda msg: self.events.add("warning", f"camera: {msg}"),
            on_detection=self._fuse_on_arrival,
        )
        # the loop and PX4's state: ticked here, fused on the camera thread, taken on the
        # receiver threads, read by the sender
        self._loop_lock = threading.RLock()
        self._fusing = False  # run(): detections are fused on the camera thread
        self._hold_s: float | None = None  # run(): how long the tick's command is held
        self._stop = threading.Event()
        self._tick_n = 0
        self._last_overrun_report = -1e9
        self.timing = LoopTiming(self.period_s, keep=int(600 * config.control_rate_hz))
        self._pending_latency: list[tuple[float, float, float]] = []
        self._last_det = None
        self._last_hb_sent = -1e9
        self._next_timesync_s = 0.0
        self.target_size_frac = 0.0
        for note in self.params.notes:
            self.events.add("warning", note)
        self.video_overlay = Overlay()
        self.video = None if config.video is None else runtime_streamer(self)
        self.foxglove = None  # a FoxglovePublisher (onboard run --foxglove)
        if config.foxglove is not None:
            from ..channels.live import FoxgloveLive  # foxglove-sdk only when asked for
            from .foxglove import FoxglovePublisher

            host, port = config.foxglove
            try:
                live = FoxgloveLive(port=port, host=host)
            except Exception as exc:  # the SDK's bind error: one clear line
                raise OSError(f"--foxglove: cannot listen on {host}:{port}: {exc}") from None
            self.foxglove = FoxglovePublisher(
                live, self._latest_image, on_error=lambda m: self.events.add("warning", m)
            )

    # ------------------------------------------------------------------ the loop object
    def _build_loop(self, width: int, height: int) -> None:
        """The interception loop for a ``width`` x ``height`` (px) camera, as configured."""
        rt = self.params.runtime
        cam = CameraModel(width, height, rt.CAM_HFOV_DEG, rt.CAM_PITCH_DEG, rt.CAM_ROLL_DEG)
        vehicle = VehicleParams.from_hover_thrust(rt.HOVER_THR)
        self.loop = InterceptionLoop(
            cam, vehicle, self.params.gains, law=rt.law,
            control_rate_hz=self.config.control_rate_hz, dkf_config=rt.dkf_config(),
        )  # fmt: skip
        self.events.add("info", f"camera {width}x{height}, law {rt.law}: loop ready")
        if self.foxglove is not None:
            self.foxglove.new_sortie(
                self.clock.now(), rt.law, cam, self.params.gains, self.config.control_rate_hz
            )

    def _param_changed(self, name: str) -> None:
        """A parameter the ground set (on a receiver thread or in a tick, under the loop's
        lock): gains and the filter's configuration from the next tick on; a new camera,
        airframe or law rebuilds the loop."""
        rt = self.params.runtime
        if self.loop is not None:
            self.loop.set_gains(self.params.gains)
            self.loop.set_dkf_config(rt.dkf_config())
        self.sm.done_size_frac, self.sm.hold_speed_m_s = rt.DONE_SIZE, rt.HOLD_SPEED
        if name.startswith("CAM_") or name in ("HOVER_THR", "LAW"):
            self.loop = None  # rebuilt at the next tick with the new camera, airframe or law

    def _command(self, command: int) -> tuple[bool, str]:
        """The ground's start or abort."""
        if command != CMD_START:
            return self.sm.command_abort()
        if self.loop is None:
            return False, "start refused: camera not ready"
        return self.sm.command_start()

    def _latest_image(self):
        """The camera thread's newest (capture time s, image), for Foxglove live."""
        f = self.camera.last_frame
        return None if f is None else (f.capture_time_s, f.image)

    # ------------------------------------------------------------------ the links' input
    def _take_fc_batch(self, msgs: list) -> None:
        """On a receiver thread (run()): PX4's messages taken as they arrive, under the loop's
        lock, so a tick sees each of them entirely or not at all."""
        with self._loop_lock:
            self._take_all(self.fc.link, self.fc.take, msgs, self.clock.now(), True)

    def _take_gcs_batch(self, msgs: list) -> None:
        """The ground's, likewise."""
        with self._loop_lock:
            self._take_all(self.ground.link, self.ground.take, msgs, self.clock.now())

    def _take_all(self, link: MavLink, take, msgs: list, now: float, loop: bool = False) -> None:
        for msg in msgs:
            try:
                if loop:
                    take(msg, now, self.loop)
                else:
                    take(msg, now)
            except (ValueError, TypeError, OverflowError, KeyError, IndexError) as exc:
                # a well-formed frame with nonsense inside (NaN where an integer belongs)
                link.bad_frames += 1
                self.events.add("warning", f"{msg.get_type()} ignored: {type(exc).__name__}")

    def _fuse_on_arrival(self, ev) -> None:
        """On the camera thread, as a detection arrives (run() only): fused into the DKF now,
        under the loop's lock, so the next tick only predicts."""
        loop = self.loop
        if not self._fusing or loop is None or ev.detection is None:
            return
        if ev.image_size != (loop.camera.width_px, loop.camera.height_px):
            return  # the tick reports it and ignores the frame
        with self._loop_lock:
            loop.on_detection(ev.detection)
            loop.fuse_detections()

    # ------------------------------------------------------------------ the tick
    def tick(self) -> None:
        """One tick of the runtime (run() calls it at each deadline; tests call it alone)."""
        now = self.clock.now()
        if self._fc_rx is None:  # else taken on the receiver thread as they arrive
            self._take_all(self.fc.link, self.fc.take, self.fc.link.poll(), now, True)
        gcs = self.ground.link
        if gcs is not None and self._gcs_rx is None:
            self._take_all(gcs, self.ground.take, gcs.poll(), now)
        if self.loop is None and self.camera.last_frame is not None:
            h, w = self.camera.last_frame.image.shape[:2]
            self._build_loop(w, h)
        loop = self.loop
        for ev in self.camera.drain():
            if loop is None:
                continue
            if ev.image_size != (loop.camera.width_px, loop.camera.height_px):
                self.events.add("error", f"camera size changed to {ev.image_size}: frame ignored")
                continue
            if ev.detection is not None:
                if not self._fusing:  # else already fused on the camera thread
                    loop.on_detection(ev.detection)
                self._last_det = ev.detection
                self.target_size_frac = ev.detection.bbox_px[2] / loop.camera.width_px
                self._pending_latency.append(
                    (ev.capture_time_s, ev.received_time_s, ev.detected_time_s)
                )
        f = self.fc.state
        tel = None
        if loop is not None and f.pos_enu_m is not None and f.q_wxyz is not None:
            tel = loop.tick(state_at(f, now), self.sm.state is State.BRAKING, self._hold_s)
        if self.video is not None:
            self.video_overlay = overlay_of(
                self._last_det, tel and tel.e_est_px, loop and loop.camera, now
            )
        inputs = self._sm_inputs(now, tel)
        decision = self.sm.step(inputs)
        for ev in decision.events:
            self.events.add(*ev)
        if decision.request_streams:  # none of these requests feeds the command: after the tick
            self.sender.submit(self.fc.request_streams)
        if decision.output is not Output.NONE and tel is not None:
            self._send(tel, now)
        if self.sm.state is not State.INTERCEPT or not inputs.tracking:
            self._pending_latency.clear()
        self._requests(decision)
        self._heartbeats(now)
        if now >= self._next_timesync_s:
            self._next_timesync_s = now + TIMESYNC_EVERY_S
            self.sender.submit(self.fc.timesync_request)
        if self._tick_n % TELEMETRY_EVERY == 0:
            self._telemetry(now, tel)
        if self.events:
            self.sender.submit(self._flush_events)
        self._tick_n += 1

    def _send(self, tel: ControlTelemetry, now: float) -> None:
        """The command to PX4, timed; the latency of the detections it is the first to use."""
        before = self.clock.now()
        self.fc.send_command(tel.command.body_rates_flu_rad_s, tel.command.thrust_normalised, now)
        sent_at = self.clock.now()
        self.timing.setpoint_sent(sent_at - before)
        if tel.mode is LoopMode.TRACKING and self.loop.last_fusion:
            for cap, rec, det in self._pending_latency:
                self.timing.command_sent(sent_at, cap, rec, det)
            self._pending_latency.clear()

    def _requests(self, decision) -> None:
        """The state machine's arm and mode requests, sent after the tick."""
        fc, custom = self.fc, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if decision.request_arm:
            self.sender.submit(fc.command, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        if decision.request_offboard:
            fc.mode_requested = MODE_OFFBOARD
            self.sender.submit(fc.command, mavlink.MAV_CMD_DO_SET_MODE, custom, PX4_MAIN_OFFBOARD)
        if decision.request_hold:
            fc.mode_requested = MODE_HOLD
            self.sender.submit(
                fc.command, mavlink.MAV_CMD_DO_SET_MODE, custom, PX4_MAIN_AUTO, PX4_SUB_AUTO_LOITER
            )

    def _sm_inputs(self, now: float, tel: ControlTelemetry | None) -> Inputs:
        """What the state machine is told at a tick at ``now`` whose loop gave ``tel`` (None:
        no loop tick): the flight controller's state, the loop's mode, the target's size."""
        f = self.fc.state
        mode = None if tel is None else tel.mode
        return Inputs(
            now_s=now,
            fc_silence_s=None if f.heartbeat_rx_s is None else now - f.last_rx_s,
            armed=f.armed,
            offboard=f.offboard,
            tracking=mode is LoopMode.TRACKING,
            target_lost=mode is LoopMode.LOST,
            target_stale=mode in _STALE_MODES,
            target_size_frac=self.target_size_frac,
            speed_m_s=0.0 if f.vel_enu_m_s is None else math.hypot(*f.vel_enu_m_s.tolist()),
        )

    def _heartbeats(self, now: float) -> None:
        if now - self._last_hb_sent < 1.0:
            return
        self._last_hb_sent = now
        status = mavlink.MAV_STATE_ACTIVE if self.sm.flying else mavlink.MAV_STATE_STANDBY
        code = tm.STATE_CODES.index(self.sm.state.value)
        self.sender.submit(self._send_heartbeats, code, status)

    def _send_heartbeats(self, state_code: int, status: int) -> None:
        self.fc.link.heartbeat(
            mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, state_code,
            status,
        )  # fmt: skip
        self.ground.heartbeat(state_code, status)

    def _telemetry(self, now: float, tel: ControlTelemetry | None) -> None:
        """This tick's telemetry to the ground (encoded and sent by the sender thread) and, with
        ``--foxglove``, to Foxglove live (which then needs the filter's state now)."""
        loop, f, timing, fox = self.loop, self.fc.state, self.timing, self.foxglove
        if self.ground.link is None and fox is None:
            return
        dkf = None if fox is None or loop is None else loop.dkf.state_vector()
        latency = timing.latency_total_s[-1] if timing.latency_total_s else None
        if self.ground.link is not None:
            snap = TelemetrySnapshot(
                now, self.sm.state, timing.recent_periods(), timing.overruns,
                self.params.version, self.params.runtime.law, self.camera.frames,
                self.camera.detections, self.fc.commands_sent, self.target_size_frac, latency,
                loop, None if loop is None else loop.guard_trips, self._last_det, dkf, tel,
                f.pos_enu_m, f.vel_enu_m_s, f.q_wxyz,
            )  # fmt: skip
            self.sender.submit(self.ground.send_telemetry, snap, self.period_s, self._loop_lock)
        if fox is not None and tel is not None:  # references only: never waits
            fox.offer(
                now, f.pos_enu_m, f.vel_enu_m_s, f.q_wxyz, tel, self._last_det, dkf,
                self.params.gains, loop.guard_trips,
            )  # fmt: skip

    def _flush_events(self) -> None:
        for severity, text in self.events.drain():
            now = self.clock.now()
            self.log(f"[{now:8.3f}] {severity.upper()}: {text}")
            if self.foxglove is not None:
                self.foxglove.event(now, severity, text)
            self.ground.publish(severity, text)

    # ------------------------------------------------------------------ run
    def stop(self) -> None:
        self._stop.set()

    def run(self, duration_s: float | None = None) -> int:
        """Run until :meth:`stop` (or SIGTERM via the CLI) or for ``duration_s``."""
        cfg, sched = self.config, self.scheduler
        on_error = lambda msg: self.events.add("error", msg)  # noqa: E731
        self._fc_rx = LinkReceiver(self.fc.link, self._take_fc_batch, on_error)
        self._fc_rx.start()
        if self.ground.link is not None:
            self._gcs_rx = LinkReceiver(self.ground.link, self._take_gcs_batch, on_error)
            self._gcs_rx.start()
        self.sender.start()
        self._fusing = True
        self.camera.start()
        if self.video is not None:
            self.video.start()
        if self.foxglove is not None:
            self.foxglove.start()
            self.events.add("info", f"Foxglove live on {self.foxglove.live.url()}")
        helpers = (self._fc_rx, self._gcs_rx, self.sender, self.camera)
        tids = [t.native_id for t in helpers if t is not None and t.native_id is not None]
        self.realtime = make_realtime(cfg.realtime_priority, cfg.cpu, cfg.lock_memory, tids)
        warning = self.realtime.warning()
        if warning:
            print(warning, file=sys.stderr, flush=True)
        self.events.add("info", f"onboard up: {cfg.control_rate_hz:g} Hz, FC {self.fc.link.url}")
        sched.start()
        end = None if duration_s is None else sched.next_deadline_s + duration_s
        try:
            while not self._stop.is_set():
                deadline = sched.next_deadline_s
                start = sched.wait()
                self._hold_s = sched.hold_s(start)
                cpu0 = time.thread_time()
                self.timing.tick_started(start, start - deadline)
                with self._loop_lock:
                    self.tick()
                now = self._tick_ended(start, cpu0)
                if end is not None and now >= end:
                    break
                sched.after_tick()
        except KeyboardInterrupt:
            pass
        finally:
            sched.stop()
            self.realtime.undo()
            self._shut_down()
        return 0

    def _tick_ended(self, start: float, cpu0: float) -> float:
        """After a tick begun at ``start`` (monotonic s): its work recorded, what it handed off
        given to the sender thread, an overrun reported (at most every 5 s). Returns when it
        ended."""
        now = time.monotonic()
        work = now - start
        overran = self.timing.tick_done(work, time.thread_time() - cpu0)
        if overran and now - self._last_overrun_report > OVERRUN_REPORT_EVERY_S:
            self._last_overrun_report = now
            self.events.add("warning", f"loop overrun: tick took {1000 * work:.1f} ms")
        self.sender.flush()
        return now

    def _shut_down(self) -> None:
        self._fc_rx.stop()
        if self._gcs_rx is not None:
            self._gcs_rx.stop()
        self.sender.stop()
        self.camera.stop()
        if self.video is not None:
            self.video.stop()
        if self.foxglove is not None:
            self.foxglove.stop()
            self.foxglove.join(timeout=2.5)
            self.foxglove.live.stop()
        if self.camera.is_alive():
            self.camera.join(timeout=2.5)  # a blocked read ends by its own timeout
        self.events.add("info", f"onboard stopping ({self.sm.state.value})")
        self._flush_events()
        if self.config.stats_path is not None:
            self.config.stats_path.write_text(json.dumps(self.stats(), indent=1))
        self.fc.link.close()
        if self.ground.link is not None:
            self.ground.link.close()
        if self.tlog is not None:
            self.tlog.close()

    # ------------------------------------------------------------------ figures
    @property
    def overruns(self) -> int:
        return self.timing.overruns

    def stats(self) -> dict:
        loop, ts, rt = self.loop, self.fc.timesync, self.realtime or RealtimeSetup()
        return {
            **self.timing.figures(),
            **self.scheduler.figures(),
            **rt.figures(),
            "frames": self.camera.frames,
            "commands_sent": self.fc.commands_sent,
            # ticks whose LOS change was re-based through the gyro: the attitude jumped beyond
            # the gyro's turn (a stale one replaced), or was not of the tick (stale)
            "attitude_jumps": None if loop is None else loop.gyro_turn.attitude_jumps,
            "stale_attitude_ticks": None if loop is None else loop.gyro_turn.stale_attitude_ticks,
            "guard_trips": None if loop is None else loop.guard_trips,
            "bad_frames_fc": self.fc.link.bad_frames,
            "bad_frames_gcs": None if self.ground.link is None else self.ground.link.bad_frames,
            "state": self.sm.state.value,
            "reason": self.sm.reason,
            "clock_zero_monotonic_s": time.monotonic() - self.clock.now(),
            "timesync_offset_s": ts.offset_now_s,
            "timesync_skew_ppm": 1e6 * ts.skew,
            "timesync_min_rtt_ms": None if ts.min_rtt_s is None else 1000 * ts.min_rtt_s,
            "timesync_accepted": ts.accepted,
            "foxglove": None if self.foxglove is None else self.foxglove.stats(),
        }
