"""``onboard run``: the interception loop on the vehicle. The control thread ticks at a fixed
rate (default 200 Hz), and at once when the camera thread has fused a detection (the early
tick: the grid re-anchors a period after it, so every command is held a period); each tick
reads the vehicle state the receiver threads took from what the flight controller and the
ground sent, feeds the camera thread's detections to the loop,
steps the offboard state machine (the failsafe wiring: :meth:`OnboardRuntime.tick`), sends
the command to PX4 and hands the rest (telemetry every few ticks, events, heartbeats, TIMESYNC
requests, the state machine's arm, mode and stream requests) to the sender thread, which sends
it in the tick's slack. Just before each grid tick a copy of the loop rehearses it, its result
dropped, so the tick finds its code and data in the caches (:mod:`.rehearsal`).

The runtime is split by concern: :mod:`.fc_side` (PX4 in and out), :mod:`.ground_side`
(parameters, commands, telemetry, events), :mod:`.scheduler` (when the tick runs: deadlines,
sleeping, garbage collection, priority, the other threads held off the tick), :mod:`.timing`
(the figures), :mod:`.camera` (the camera thread), :mod:`.receiver` and :mod:`.sender` (the
links' threads) and this module, which wires them around the state machine.
All MAVLink goes through :mod:`onboard.link.px4`; the maths stays in :mod:`onboard.loop`.
"""

from __future__ import annotations

import copy
import json
import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from ..camera_model import CameraModel
from ..datatypes import ControlTelemetry, LoopMode, VehicleParams
from ..link import ftp
from ..link import telemetry as tm
from ..link.param_meta import FILE_NAMES, component_files
from ..link.params import ParamTable
from ..link.px4 import (
    MODE_HOLD,
    MODE_OFFBOARD,
    ONBOARD_COMPONENT_ID,
    PX4_MAIN_AUTO,
    PX4_MAIN_OFFBOARD,
    PX4_SUB_AUTO_LOITER,
    VEHICLE_SYSTEM_ID,
    MavLink,
    TlogWriter,
    mavlink,
)
from ..link.timesync import TimesyncEstimator, send_request
from ..loop import InterceptionLoop
from ..perception.detector import RedBalloonDetector
from .camera import CameraThread, Clock, open_source
from .fc_side import FlightControllerSide
from .fc_state import FcState, state_at
from .ground_side import DKF_FROM_LOOP, TELEMETRY_EVERY, GroundSide
from .receiver import LinkReceiver
from .rehearsal import REHEARSE_LEAD_S, Rehearsal, warm_up
from .scheduler import BindingWatch, PeriodicScheduler, keep_off, run_delay_s, split_cpus
from .sender import Sender
from .state_machine import Inputs, OffboardStateMachine, Output, State
from .timing import EARLY_TICK_HERE, LoopTiming, percentile, to_ms
from .video import Overlay, VideoConfig, overlay_of, runtime_streamer

# the loop flies without a live track (coast, re-acquisition, search: see onboard/loop.py)
_STALE_MODES = (LoopMode.COAST, LoopMode.REACQUIRE, LoopMode.SEARCH)

TIMESYNC_EVERY_S = 0.1  # TIMESYNC requests to PX4 at 10 Hz
# the other threads' work sized to the slack (README "Work sized to the slack"): begun no
# later than this before the control thread wakes, it is done by then
TAKE_BUDGET_S = 0.0002  # a receiver's batch taken under the loop's lock: p99 0.16 ms (bench)
SEND_BUDGET_S = 0.0005  # a sender's item, telemetry the dearest: p99 0.47 ms (bench --sitl)
# the rehearsal waits this long at most for the loop's lock held by another thread's batch
# (asleep, the GIL let go, so that thread ends it) rather than leave the tick to wait for it
REHEARSAL_LOCK_WAIT_S = 0.00015
SHADOW_MIN_SLACK_S = 0.002  # the shadow is copied (about 0.5 ms) only with this much slack left
# the rehearsal's setpoint frame goes to the runtime's own socket only this long or more before
# the deadline: a send after a sleep took 0.036-0.064 ms here (README "Session 21")
REHEARSED_SEND_MIN_LEAD_S = 0.0001


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
    realtime_priority: int | None = None  # SCHED_FIFO priority of the control thread (1-99)
    video: VideoConfig | None = None  # the camera as H.264/RTP (onboard run --video)
    foxglove: tuple[str, int] | None = None  # (host, port): Foxglove live (onboard run --foxglove)
    # one CPU left to the control thread: the process's other threads kept off it and the control
    # thread bound to it, freed while another program keeps it waiting there (onboard run
    # --reserve-cpu; scheduler.py "CPU placement"); not under an accepted realtime_priority
    reserve_cpu: bool = True
    # tick as soon as a detection is fused, not at the next deadline (onboard run --early-tick).
    # The SITL sortie's crashes under load were the starved SITL's, with it on or off (README)
    early_tick: bool = True
    # rehearse the tick on a copy of the loop just before each deadline (onboard run
    # --rehearse; rehearsal.py): the tick then finds its code and data in the caches
    rehearse: bool = True


class OnboardRuntime(FlightControllerSide, GroundSide):
    """The vehicle's runtime: the links, the camera thread, the loop and the state machine."""

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
        # started by run(), which takes what the links bring as it arrives; tick() polls without
        self._fc_rx: LinkReceiver | None = None
        self._gcs_rx: LinkReceiver | None = None
        self._fc_waiting: deque = deque()  # parsed, not taken yet (_take_fc_batch)
        self._gcs_waiting: deque = deque()
        self.rehearsal = Rehearsal() if config.rehearse else None
        self.scheduler = PeriodicScheduler(
            self.period_s,
            realtime_priority=config.realtime_priority,
            rehearse=None if self.rehearsal is None else self._rehearse,
            rehearse_lead_s=REHEARSE_LEAD_S,
        )
        # run(): telemetry, events, heartbeats and TIMESYNC requests sent after the tick
        self.sender = Sender(
            on_error=lambda msg: self._event("error", msg),
            gate=partial(self.scheduler.wait_for_slack, SEND_BUDGET_S),
        )
        self.camera = CameraThread(
            lambda: open_source(config.camera, self.clock, self.params.runtime.CAM_LAT_S),
            RedBalloonDetector(),
            self.clock,
            on_error=lambda msg: self._event("warning", f"camera: {msg}"),
            on_detection=self._fuse_on_arrival,
        )
        # the loop and PX4's state: ticked here, fused on the camera thread, taken on the
        # receiver threads, read by the sender
        self._loop_lock = threading.RLock()
        self._fusing = False  # run(): detections are fused on the camera thread
        self._hold_s: float | None = None  # run(): how long a command is held (the period)
        self._stop = threading.Event()
        self._tick_n = 0
        self._events: deque[tuple[str, str]] = deque()
        self._last_event = deque(maxlen=1)
        self.commands_sent = 0
        self._last_overrun_report = -1e9
        self._tick_failure: Exception | None = None  # of a tick on the camera thread
        self.reserved_cpu: int | None = None  # run(): the CPU left to the control thread
        self.binding: BindingWatch | None = None  # run(): whether it stays bound there
        self.control_bound: bool | None = None  # run(): bound to it (None: no CPU left to it)
        self._cpus: set[int] = set()  # run(): the process's CPUs
        # ten minutes of figures, not the whole day
        self.timing = LoopTiming(self.period_s, keep=int(600 * config.control_rate_hz))
        self._pending_latency: list[tuple[float, float, float]] = []
        self._last_det = None
        self._last_forward: dict[tuple[int, str], float] = {}
        self._last_hb_sent = -1e9
        self._mode_requested = 0
        self.target_size_frac = 0.0
        for note in self.params.notes:
            self._event("warning", note)
        self.video_overlay = Overlay()
        self.video = None if config.video is None else runtime_streamer(self)
        self.foxglove = None  # a FoxglovePublisher (onboard run --foxglove)
        if config.foxglove is not None:
            from ..channels.live import FoxgloveLive  # foxglove-sdk only when asked for

            host, port = config.foxglove
            try:
                live = FoxgloveLive(port=port, host=host)
            except Exception as exc:  # the SDK's bind error: one clear line
                raise OSError(f"--foxglove: cannot listen on {host}:{port}: {exc}") from None
            from .foxglove import FoxglovePublisher

            self.foxglove = FoxglovePublisher(
                live,
                self._latest_image,
                on_error=lambda msg: self._event("warning", msg),
            )

    # ------------------------------------------------------------------ the loop object
    def _new_loop(self, width: int, height: int) -> InterceptionLoop:
        """An interception loop for a ``width`` x ``height`` (px) camera, as configured."""
        rt = self.params.runtime
        cam = CameraModel(width, height, rt.CAM_HFOV_DEG, rt.CAM_PITCH_DEG, rt.CAM_ROLL_DEG)
        vehicle = VehicleParams.from_hover_thrust(rt.HOVER_THR)
        return InterceptionLoop(
            cam,
            vehicle,
            self.params.gains,
            law=rt.law,
            control_rate_hz=self.config.control_rate_hz,
            dkf_config=rt.dkf_config(),
        )

    def _build_loop(self, width: int, height: int) -> None:
        rt = self.params.runtime
        self.loop = self._new_loop(width, height)
        self._event("info", f"camera {width}x{height}, law {rt.law}: loop ready")
        if self.foxglove is not None:
            self.foxglove.new_sortie(
                self.clock.now(),
                rt.law,
                self.loop.camera,
                self.params.gains,
                self.config.control_rate_hz,
            )

    def _latest_image(self):
        """The camera thread's newest (capture time s, image), for Foxglove live."""
        f = self.camera.last_frame
        return None if f is None else (f.capture_time_s, f.image)

    def _heartbeats(self, now: float) -> None:
        if now - self._last_hb_sent < 1.0:
            return
        self._last_hb_sent = now
        status = mavlink.MAV_STATE_ACTIVE if self.sm.flying else mavlink.MAV_STATE_STANDBY
        self.sender.submit(self._send_heartbeats, tm.STATE_CODES.index(self.sm.state.value), status)

    def _send_heartbeats(self, state_code: int, status: int) -> None:
        for link in (self.fc, self.gcs):
            if link is not None:
                link.heartbeat(
                    mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                    mavlink.MAV_AUTOPILOT_INVALID,
                    0,
                    state_code,
                    status,
                )

    def _timesync_request(self) -> None:
        send_request(self.fc, self.clock.now())  # stamped as it goes out

    def _take_fc_batch(self, msgs: list) -> None:
        """On a receiver thread (run()): PX4's messages taken as they arrive, under the loop's
        lock, so a tick sees each of them entirely or not at all. When the lock is taken (a
        tick, a fusion) they wait in order for whoever has it next, the next tick at the
        latest: a late control thread running tick after tick must not leave them behind. They
        wait likewise when taking them here would still hold the lock when the control thread
        wakes (``TAKE_BUDGET_S``): the tick takes them at its start."""
        self._offer(self._fc_waiting, msgs)

    def _take_gcs_batch(self, msgs: list) -> None:
        """The ground's, likewise."""
        self._offer(self._gcs_waiting, msgs)

    def _offer(self, waiting: deque, msgs: list) -> None:
        waiting.extend(msgs)
        if not self.scheduler.time_for(TAKE_BUDGET_S):
            return  # the take would still hold the lock at the wake-up: the tick takes them
        if self._loop_lock.acquire(blocking=False):
            try:
                self._take_waiting(self.clock.now())
            finally:
                self._loop_lock.release()

    def _take_waiting(self, now: float) -> None:
        """Take the links' messages the receiver threads left waiting (under the loop's lock)."""
        for link, take, waiting in (
            (self.fc, self._take_fc, self._fc_waiting),
            (self.gcs, self._take_gcs, self._gcs_waiting),
        ):
            while waiting:
                msgs = [waiting.popleft() for _ in range(len(waiting))]
                self._take_all(link, take, msgs, now)

    def _take_all(self, link: MavLink, take, msgs: list, now: float) -> None:
        for msg in msgs:
            try:
                take(msg, now)
            except (ValueError, TypeError, OverflowError, KeyError, IndexError) as exc:
                # a well-formed frame with nonsense inside (NaN where an integer belongs)
                link.bad_frames += 1
                self._event("warning", f"{msg.get_type()} ignored: {type(exc).__name__}")

    def _fuse_on_arrival(self, ev) -> None:
        """On the camera thread, as a detection arrives (run() only): fuse it into the DKF
        now and ask for a tick at once (the early tick: the scheduler re-anchors its grid
        there, and the tick's command is held a period, eq. 17's dt: see
        ``InterceptionLoop.tick``'s ``hold_s``). The request is made under the loop's lock, so
        a tick that takes the lock after it has the fusion in it and withdraws it."""
        loop = self.loop
        if not self._fusing or loop is None or ev.detection is None:
            return
        if ev.image_size != (loop.camera.width_px, loop.camera.height_px):
            return  # the tick reports it and ignores the frame
        sched = self.scheduler
        sched.input_begins()  # a tick falling due now waits for this fusion, asleep
        fused = False
        try:
            with self._loop_lock:
                loop.on_detection(ev.detection)
                fused = bool(loop.fuse_detections())
                if fused and self.config.early_tick:
                    # after a failed tick here the control thread raises it at its wake-up
                    start = None if self._tick_failure is not None else sched.tick_here()
                    if start is None:  # the control thread is awake: it ticks at once
                        sched.request_tick()
                    else:
                        self._tick_here(start)
        finally:
            sched.input_done()

    def _tick_here(self, start: float) -> None:
        """On the camera thread, under the loop's lock, right after a fusion: the early tick
        (scheduler.py "Early ticks"), timed as the control thread times its ticks. A tick that
        raises is raised again on the control thread, as if it had been its own."""
        cpu0 = time.thread_time()
        self.timing.tick_started(start, True, EARLY_TICK_HERE)
        self.timing.lock_waited(0.0)  # taken for the fusion already
        try:
            self.tick()
        except Exception as exc:
            self._tick_failure = exc
        finally:
            try:
                self._tick_ended(start, cpu0)
            finally:
                self.scheduler.tick_here_done()

    def _tick_ended(self, start: float, cpu0: float) -> float:
        """After a tick begun at ``start`` (perf_counter, s) on a thread whose CPU time was
        ``cpu0`` then: its work recorded, what it handed off given to the sender thread, an
        overrun reported (at most every 5 s). Returns when it ended."""
        now = time.perf_counter()
        work = now - start
        overran = self.timing.tick_done(work, time.thread_time() - cpu0)
        if overran and now - self._last_overrun_report > 5.0:
            self._last_overrun_report = now
            self._event("warning", f"loop overrun: tick took {1000 * work:.1f} ms")
        self.sender.flush()
        return now

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
            "scheduler_stalls": self.scheduler.stalls,
            "early_ticks_on_camera_thread": self.scheduler.ticks_here,
            "ticks_waiting_for_a_fusion": self.scheduler.input_waits,
            "fusion_wait_max_ms": 1000.0 * self.scheduler.input_wait_max_s,
            "early_tick": self.config.early_tick,
            **self._rehearsal_stats(),
            "gc_runs_in_slack": self.scheduler.gc_runs,
            # ticks whose LOS change was re-based through the gyro: the attitude jumped beyond
            # the gyro's turn (a stale one replaced), or was not of the tick (stale)
            "attitude_jumps": None if self.loop is None else self.loop.attitude_jumps,
            "stale_attitude_ticks": None if self.loop is None else self.loop.stale_attitude_ticks,
            "guard_trips": None if self.loop is None else self.loop.guard_trips,
            "realtime_priority": self.config.realtime_priority,
            "reserved_cpu": self.reserved_cpu,
            # the control thread bound to it at the flight's end, the times it was freed and the
            # most it waited for it (a fraction of a look's half second)
            "control_thread_bound": self.control_bound,
            "binding_escapes": None if self.binding is None else self.binding.escapes,
            "binding_wait_max_fraction": None
            if self.binding is None
            else self.binding.max_wait_fraction_seen,
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
            "foxglove": None if self.foxglove is None else self.foxglove.stats(),
        }

    def _rehearsal_stats(self) -> dict:
        rh, sched = self.rehearsal, self.scheduler
        took, late = list(sched.rehearsal_s), list(sched.wake_overshoot_s)
        return {
            "wake_overshoot_median_ms": to_ms(percentile(late, 0.5)),
            "wake_overshoot_p99_ms": to_ms(percentile(late, 0.99)),
            "rehearse": rh is not None,
            "rehearsals": None if rh is None else rh.runs,
            "rehearsals_skipped": None if rh is None else sched.rehearsals_skipped,
            "rehearsals_declined_lock_held": None if rh is None else rh.lock_declines,
            "rehearsal_lock_waits": None if rh is None else rh.lock_waits,
            "rehearsal_lock_wait_max_ms": None if rh is None else to_ms(rh.lock_wait_max_s),
            "rehearsal_median_ms": to_ms(percentile(took, 0.5)),
            "rehearsal_p99_ms": to_ms(percentile(took, 0.99)),
            "shadow_refreshes": None if rh is None else rh.refreshes,
            "rehearsal_errors": None if rh is None else rh.errors,
            "rehearsed_sends": None if rh is None else rh.sends,
        }

    # ------------------------------------------------------------------ the tick
    def tick(self) -> None:
        """One tick of the runtime (run() calls it on the grid and early, for a detection)."""
        now = self.clock.now()
        self._take_waiting(now)  # what the receiver threads could not take (the lock was held)
        if self._fc_rx is None:  # else taken on the receiver thread as they arrive
            self._take_all(self.fc, self._take_fc, self.fc.poll(), now)
        if self.gcs is not None and self._gcs_rx is None:
            self._take_all(self.gcs, self._take_gcs, self.gcs.poll(), now)
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
                if not self._fusing:  # else already fused on the camera thread
                    loop.on_detection(ev.detection)
                self._last_det = ev.detection
                bw = ev.detection.bbox_px[2]
                self.target_size_frac = bw / loop.camera.width_px
                self._pending_latency.append(
                    (ev.capture_time_s, ev.received_time_s, ev.detected_time_s)
                )
        f = self.fcs
        tel = None
        if loop is not None and f.pos_enu_m is not None and f.q_wxyz is not None:
            tel = loop.tick(state_at(f, now), self.sm.state is State.BRAKING, self._hold_s)
        if self.video is not None:
            self.video_overlay = overlay_of(
                self._last_det, tel and tel.e_est_px, loop and loop.camera, now
            )
        inputs = self._sm_inputs(now, tel)
        tracking = inputs.tracking
        decision = self.sm.step(inputs)
        for ev in decision.events:
            self._event(*ev)
        if decision.request_streams:  # none of these requests feeds the command: after the tick
            self.sender.submit(self._request_streams)
        if decision.output is not Output.NONE and tel is not None:
            before = self.clock.now()
            self._send_command(tel.command.body_rates_flu_rad_s, tel.command.thrust_normalised, now)
            sent_at = self.clock.now()
            self.timing.setpoint_sent(sent_at - before)
            if tel.mode is LoopMode.TRACKING and loop.last_fusion:
                for cap, rec, det in self._pending_latency:
                    self.timing.command_sent(sent_at, cap, rec, det)
                self._pending_latency.clear()
        if self.sm.state is not State.INTERCEPT or not tracking:
            self._pending_latency.clear()
        if decision.request_arm:
            self.sender.submit(self._fc_command, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        if decision.request_offboard:
            self._mode_requested = MODE_OFFBOARD
            self.sender.submit(
                self._fc_command,
                mavlink.MAV_CMD_DO_SET_MODE,
                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                PX4_MAIN_OFFBOARD,
            )
        if decision.request_hold:
            self._mode_requested = MODE_HOLD
            self.sender.submit(
                self._fc_command,
                mavlink.MAV_CMD_DO_SET_MODE,
                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                PX4_MAIN_AUTO,
                PX4_SUB_AUTO_LOITER,
            )
        self._heartbeats(now)
        if now >= self._next_timesync_s:
            self._next_timesync_s = now + TIMESYNC_EVERY_S
            self.sender.submit(self._timesync_request)
        if self._tick_n % TELEMETRY_EVERY == 0:
            fox = self.foxglove
            dkf = DKF_FROM_LOOP  # the sender's, after the tick
            if fox is not None:  # Foxglove live takes it now
                dkf = None if loop is None else loop.dkf.state_vector()
            self._telemetry(now, tel, dkf)
            if fox is not None and tel is not None:  # references only: never waits
                fox.offer(
                    now, f.pos_enu_m, f.vel_enu_m_s, f.q_wxyz, tel, self._last_det, dkf,
                    self.params.gains, loop.guard_trips,
                )  # fmt: skip
        if self._events:
            self.sender.submit(self._flush_events)
        self._tick_n += 1

    def _sm_inputs(self, now: float, tel: ControlTelemetry | None) -> Inputs:
        """What the state machine is told at a tick at ``now`` whose loop gave ``tel`` (None:
        no loop tick): the flight controller's state, the loop's mode, the target's size."""
        f = self.fcs
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

    def _rehearse_step(self, now: float, tel: ControlTelemetry) -> None:
        """The rehearsal's state machine step: a copy of it (the real one untouched) steps on
        the shadow's telemetry, so the tick finds that code in the caches too (after a 5 ms
        sleep the step took about 0.023 ms here, rehearsed 0.006, back to back 0.005)."""
        copy.copy(self.sm).step(self._sm_inputs(now, tel))

    def _rehearse(self) -> bool:
        """On the control thread, just before a deadline (rehearsal.py): the shadow loop ticks
        the vehicle's state as of now. Skipped (False) before the state is known, without a
        shadow, or when the loop's lock stays taken (another thread's batch that ran into the
        wake-up) for ``REHEARSAL_LOCK_WAIT_S`` or until the spin: waiting for it asleep lets
        that thread end its batch with the GIL, where declining at once left the tick to wait
        for it, spinning with the GIL in between. Skipped too when the wait ended in the spin
        or with an input on its way (a fusion began meanwhile: its early tick comes first)."""
        f, rh, sched = self.fcs, self.rehearsal, self.scheduler
        if rh.shadow is None:
            return False
        if not self._loop_lock.acquire(blocking=False):
            wait_s = min(REHEARSAL_LOCK_WAIT_S, sched.spin_in_s())
            asked = time.perf_counter()
            if wait_s <= 0.0 or not self._loop_lock.acquire(timeout=wait_s):
                if not sched.input_pending():  # else a fusion's, not a batch's
                    rh.lock_declines += 1
                return False
            rh.lock_waited(time.perf_counter() - asked)
            if sched.spin_in_s() <= 0.0 or sched.input_pending():
                self._loop_lock.release()
                return False
        try:
            if f.pos_enu_m is None or f.q_wxyz is None:
                return False
            state = state_at(f, self.clock.now())
        finally:
            self._loop_lock.release()
        rh.run(state, self._hold_s, partial(self._rehearse_step, state.time_s), self._rehearse_send)
        return True

    def _rehearse_send(self, frame: bytes) -> bool:
        """The rehearsal's setpoint frame sent to the runtime's own socket
        (``MavLink.rehearse_send``), unless the deadline is nearer than
        ``REHEARSED_SEND_MIN_LEAD_S`` or a fusion is coming in (its early tick comes first)."""
        sched = self.scheduler
        if sched.deadline_in_s() < REHEARSED_SEND_MIN_LEAD_S or sched.input_pending():
            return False
        return self.fc.rehearse_send(frame)

    def _prepare_loop(self) -> bool:
        """In the slack after a tick (run()): build the loop as soon as the camera's first
        frame gives its size, so that no tick pays for it (its shadow is taken after the next
        tick, :meth:`_refresh_shadow`; the code's first runs were paid by :func:`warm_up`). The
        tick that built it took about 1 ms here, and a start-up tick, very likely that one,
        5.5 ms once on a busy host: an overrun (README "Session 21"). :meth:`tick` still
        builds it when called alone. True when it built it."""
        if self.loop is not None or self.camera.last_frame is None:
            return False
        if self.scheduler.slack_s() < SHADOW_MIN_SLACK_S:
            return False  # after a later tick
        h, w = self.camera.last_frame.image.shape[:2]
        with self._loop_lock:
            if self.loop is not None:
                return False
            self._build_loop(w, h)
        return True

    def _refresh_shadow(self) -> None:
        """After a tick, in the slack: a new shadow when the loop's mode moved away from it or
        it is old (rehearsal.py), unless the next wake-up is near."""
        loop, rh = self.loop, self.rehearsal
        if loop is None or rh is None or not rh.needs_refresh(loop):
            return
        if self.scheduler.slack_s() < SHADOW_MIN_SLACK_S:
            return  # after a later tick
        with self._loop_lock:
            rh.refresh(loop)

    # ------------------------------------------------------------------ run
    def _reserve_cpu(self) -> set[int] | None:
        """On the control thread, the other threads started: leave one CPU to it (scheduler.py
        "CPU placement"): every other thread of the process off that CPU and the control thread
        bound to it (:meth:`_watch_binding` frees it while another program keeps it waiting
        there; without its run delay to watch by it is left free). Returns the CPUs the process
        had (to put the threads back at the end), or None when there was nothing to do or it
        was refused (a warning event; the threads are put back)."""
        self.reserved_cpu, self.binding, self.control_bound = None, None, None
        if not hasattr(os, "sched_getaffinity"):
            return None
        cpus = os.sched_getaffinity(0)
        split = split_cpus(cpus)
        if split is None:
            return None
        note = keep_off(split[1], threading.get_native_id())
        watchable = run_delay_s() is not None
        if note is None and watchable:
            try:
                os.sched_setaffinity(0, split[0])
            except OSError as exc:
                note = f"CPU placement refused ({exc}): threads left where the system puts them"
        if note:
            self._event("warning", note)
            keep_off(cpus, -1)
            return None
        self.reserved_cpu = next(iter(split[0]))
        self._cpus = cpus
        self.control_bound = watchable
        if watchable:
            self.binding = BindingWatch()
        return cpus

    def _watch_binding(self) -> None:
        """On the control thread, in the slack after a tick: free it from its CPU while
        another program keeps it waiting there, bind it again later (``BindingWatch``)."""
        watch, now = self.binding, time.perf_counter()
        if watch is None or not watch.due(now):
            return
        delay = run_delay_s()
        if delay is None:
            return
        bind = watch.step(now, delay)
        if bind is None:
            return
        try:
            os.sched_setaffinity(0, {self.reserved_cpu} if bind else self._cpus)
        except OSError as exc:  # left as it is, and no longer watched
            self.binding = None
            self._event("warning", f"control thread's CPU binding left as it is ({exc})")
            return
        watch.applied(bind, now, delay)
        self.control_bound = bind
        if not bind:
            self._event(
                "warning",
                f"control thread waited {100 * watch.last_wait_fraction:.0f} % of the time "
                f"for CPU {self.reserved_cpu} (another program there): free to run on any "
                f"CPU for {watch.unbound_for_s:g} s",
            )

    def stop(self) -> None:
        self._stop.set()

    def run(self, duration_s: float | None = None) -> int:
        sched = self.scheduler
        self._tick_failure = None
        if self.loop is None:  # the code's first runs paid before the loop runs (rehearsal.py)
            try:
                warm_up(self._new_loop(640, 480), self.period_s)
            except Exception as exc:  # a throwaway loop's failure is no reason not to fly
                self._event("warning", f"warm-up failed ({type(exc).__name__}: {exc})")
        note = sched.start()  # before the camera thread starts, so it inherits the priority
        if note:
            self._event("warning", note)
        realtime = self.config.realtime_priority is not None and note is None
        # PX4's stream and the ground's messages parsed and taken between ticks
        on_error = lambda msg: self._event("error", msg)  # noqa: E731
        gate = sched.wait_for_slack
        self._fc_rx = LinkReceiver(self.fc, self._take_fc_batch, on_error, gate)
        self._fc_rx.start()
        if self.gcs is not None:
            # a few messages a second: not worth waking it before every tick to park it
            self._gcs_rx = LinkReceiver(
                self.gcs, self._take_gcs_batch, on_error, gate, off_socket_during_ticks=False
            )
            self._gcs_rx.start()
        self.sender.start()
        if self.rehearsal is not None:
            note = self.fc.prepare_send_rehearsal()
            if note:
                self._event("warning", note)
        self._fusing = True
        self.camera.start()
        if self.video is not None:
            self.video.start()
        if self.foxglove is not None:
            self.foxglove.start()
            self._event("info", f"Foxglove live on {self.foxglove.live.url()}")
        cpus_before = self._reserve_cpu() if self.config.reserve_cpu and not realtime else None
        self._event("info", f"onboard up: {self.config.control_rate_hz:g} Hz, FC {self.fc.url}")
        end = None if duration_s is None else time.perf_counter() + duration_s
        # every command is held a period: an early tick re-anchors the grid (eq. 17's dt)
        self._hold_s = self.period_s
        try:
            while not self._stop.is_set():
                start = sched.wait()
                if self._tick_failure is not None:  # a tick on the camera thread raised
                    raise self._tick_failure
                cpu0 = time.thread_time()
                self.timing.tick_started(start, sched.early, sched.woken_as)
                with self._loop_lock:  # the camera thread fuses into the same loop
                    self.timing.lock_waited(time.perf_counter() - start)
                    sched.served()  # a detection fused before this point is in this tick
                    self.tick()
                now = self._tick_ended(start, cpu0)
                if end is not None and now >= end:
                    break
                sched.after_tick()
                if not self._prepare_loop():  # a new loop's shadow after a later tick
                    self._refresh_shadow()
                self._watch_binding()
                self.fc.drain_rehearsals()
        except KeyboardInterrupt:
            pass
        finally:
            sched.stop()
            if cpus_before is not None:  # the threads going on (a test, an embedding): as they were
                keep_off(cpus_before, -1)
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
