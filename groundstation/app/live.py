"""Live mode: the dashboard on a real (or SITL) vehicle through the onboard computer's ground
link. The same views as simulator mode are fed from MAVLink: the flight controller's pose
(passed through by the onboard component), the controller state in ``DEBUG_FLOAT_ARRAY``
(layout: :mod:`onboard.link.telemetry`), a cooperative target's own position (system 2)
when it reports one, and ``STATUSTEXT`` events.

Gain edits go out as ``PARAM_SET`` and count as applied only when the matching
``PARAM_VALUE`` comes back; start and abort are ``COMMAND_LONG`` answered by
``COMMAND_ACK``. A sortie is recorded to MCAP from the accepted start until the onboard
component reports it finished (or the link stays lost: live_recording.py).

Each telemetry message becomes a :class:`~onboard.frames.Frame`
(:mod:`.live_frames`): the recorder observes those frames, and the dashboard's snapshot is
built from the latest by the builder the simulator and replay use (:mod:`.snapshot`).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from onboard.enums import LoopMode, RuntimeState
from onboard.frames import Frame, SortieStart
from onboard.gains import GAIN_NAMES, Gains
from onboard.link import telemetry as tm
from onboard.link.params import PARAM_IDS, PARAM_SPECS, law_name
from onboard.link.px4 import (
    CMD_ABORT,
    CMD_START,
    ONBOARD_COMPONENT_ID,
    VEHICLE_SYSTEM_ID,
    mavlink,
)

from .errors import SessionError
from .live_frames import live_frame, pose_from_values
from .live_link import LINK_TIMEOUT_S, LinkState
from .live_recording import LiveRecording
from .scene import SceneState
from .snapshot import frame_snapshot

_WAITING = tm.LOOP_MODE_CODES.index(LoopMode.WAITING.value)
_SEARCH = tm.LOOP_MODE_CODES.index(LoopMode.SEARCH.value)


def _acquired(t: dict[str, Any]) -> bool:
    """Has the loop had a target estimate? Not while waiting, nor while searching with no
    detection ever (the time since one is then infinite or not available)."""
    mode = t.get("loop_mode")
    if mode is None or int(mode) == _WAITING:
        return False
    since = t.get("dkf_since_det_s")
    never = since is None or not math.isfinite(float(since))
    return not (int(mode) == _SEARCH and never)


PUBLISH_HZ = 25.0
SCENE_EVERY = 5
# a start or abort unanswered this long is sent again, at most COMMAND_SENDS times in all (the
# command protocol's retry: a lost COMMAND_LONG or COMMAND_ACK does not leave the operator's
# abort undone)
ACK_TIMEOUT_S = 1.0
COMMAND_SENDS = 3
# a PARAM_SET with no PARAM_VALUE back within this long is sent again, at most PARAM_SET_SENDS
# times in all, then reported as unanswered (the parameter protocol's rule; mavros's figures)
PARAM_SET_TIMEOUT_S = 1.0
PARAM_SET_SENDS = 4
TARGET_DIAMETER_M = 0.3  # drawn size of a cooperative target (its telemetry has no size)
FINISHED_STATES = (RuntimeState.FINISHED.value, RuntimeState.LINK_LOST.value)
ACK_NAMES = {
    mavlink.MAV_RESULT_ACCEPTED: "accepted",
    mavlink.MAV_RESULT_DENIED: "denied",
    mavlink.MAV_RESULT_UNSUPPORTED: "unsupported",
    mavlink.MAV_RESULT_FAILED: "failed",
    mavlink.MAV_RESULT_TEMPORARILY_REJECTED: "temporarily rejected",
}


# ---------------------------------------------------------------------- the session
class LiveSession:
    """Plays the part of :class:`~groundstation.app.session.SimSession` for a live link: what
    the vehicle reports is its ``vehicle`` (:class:`~.live_link.LinkState`); here what the
    operator sends, the recording and the page's view."""

    simulated = False  # the routers' Session protocol (protocol.py)
    foxglove = None  # a FoxgloveLive publishing each sortie's channels (serve --foxglove)
    video = None  # a VideoReceiver of the vehicle's camera (serve --video)

    def __init__(
        self,
        url: str,
        signing_key: bytes | None = None,
        on_snapshot: Callable[[dict[str, Any]], None] | None = None,
        scene: Any | None = None,
        log_dir: Path | None = None,
        publish_hz: float = PUBLISH_HZ,
    ) -> None:
        self.vehicle = LinkState(url, signing_key, self._on_telemetry, self._on_event)
        self.log_dir = log_dir
        self._on_snapshot = on_snapshot
        self.scene = scene
        self.publish_period_s = 1.0 / publish_hz
        self._stop = threading.Event()
        self.replay = self.compare = None
        self.state = "live"
        self.rec: LiveRecording | None = None  # the sortie being recorded
        self._params_requested = -1e9
        self._publish_count = 0
        self._scene_reset = True  # (re)build the 3D scene at the next publish
        self.miss_m: float | None = None  # the last recorded sortie's closest approach
        self._param_sends: dict[str, int] = {}  # PARAM_SETs of each pending edit so far
        self._param_sent_s: dict[str, float] = {}  # when the last of them went out
        self.param_set_resends = 0
        self.scene_errors = 0
        self.errors = 0
        self.last_error: str | None = None
        self._thread = threading.Thread(target=self._run, name="live-link", daemon=True)
        self._thread.start()

    @property
    def gains(self) -> Gains:
        """The gains as the vehicle last reported them (its PARAM_VALUEs)."""
        return self.vehicle.gains

    def _on_telemetry(self, t: dict[str, float | None], now: float) -> None:
        if self.rec is not None:
            self._record(t, now)

    def _on_event(self, level: str, text: str) -> None:
        if self.rec is not None:
            self.rec.event(level, text)

    # ------------------------------------------------------------------ simulator commands
    def _not_live(self, *_a, **_k):
        raise SessionError("live mode: the simulator controls are not available")

    start = pause = resume = step = reset = set_speed = _not_live
    open_replay = compare_with = replay_command = _not_live

    def series(self) -> dict[str, Any]:
        """Live, the page's plots grow from the telemetry it receives: no series kept here."""
        return {"t_s": [], "columns": {}, "events": []}

    def request_frame(self) -> None:
        """The vehicle's video frames go out as they are received: nothing to ask for."""

    def default_gains(self) -> Gains:
        """What "reset gains" restores: the gains the sortie started from. Live, that is the
        vehicle's own gain parameters as first read in full (its parameter file)."""
        with self.vehicle.lock:
            if self.vehicle.initial_gains is None:
                raise SessionError("the vehicle's parameters are not read yet: nothing to reset to")
            return self.vehicle.initial_gains

    # ------------------------------------------------------------------ operator commands
    def reset_edits(self) -> Gains:
        """Back to the vehicle's own gain parameters as first read (:meth:`default_gains`)."""
        return self.set_gains(self.default_gains())

    def set_gains(self, gains: Gains, source: str | None = None) -> Gains:
        """Send a PARAM_SET for every gain that differs from the vehicle's value (a gain set
        loaded by name, ``source``, goes out the same way: the vehicle keeps no sets)."""
        with self.vehicle.lock:
            if not self.vehicle.link_up():
                raise SessionError("no link to the onboard computer: gains not sent")
            missing = [n for n in GAIN_NAMES if n not in self.vehicle.params]
            if missing:
                raise SessionError(
                    "the vehicle's parameters are not read yet (missing "
                    + ", ".join(missing[:4])
                    + "): gains not sent"
                )
            for name in GAIN_NAMES:
                new = float(getattr(gains, name))
                if not math.isclose(new, self.vehicle.params[name], rel_tol=1e-6, abs_tol=1e-7):
                    self.vehicle.pending[name] = new
                    self.vehicle.refused.pop(name, None)
                    self._param_sends[name] = 0
                    self._send_param_set(name, time.monotonic())
        return gains

    def _send_param_set(self, name: str, now: float) -> None:
        """PARAM_SET of the pending value of gain ``name`` (under the lock)."""
        self._param_sends[name] += 1
        self._param_sent_s[name] = now
        self.vehicle.link.send(
            self.vehicle.link.mav.param_set_encode(
                VEHICLE_SYSTEM_ID,
                ONBOARD_COMPONENT_ID,
                PARAM_IDS[name].encode("ascii"),
                self.vehicle.pending[name],
                mavlink.MAV_PARAM_TYPE_REAL32,
            )
        )

    def _resend_unanswered(self, now: float) -> None:
        """Each pending edit unanswered for PARAM_SET_TIMEOUT_S is sent again, or after
        PARAM_SET_SENDS sends reported as unanswered (under the lock)."""
        pending = self.vehicle.pending
        for name in [n for n in pending if now - self._param_sent_s[n] >= PARAM_SET_TIMEOUT_S]:
            if self._param_sends[name] < PARAM_SET_SENDS:
                self.param_set_resends += 1
                self._send_param_set(name, now)
            else:
                del pending[name]
                why = f"{name}: no PARAM_VALUE from the vehicle after {PARAM_SET_SENDS} sends"
                self.vehicle.refused[name] = why

    def _command(self, command: int, label: str) -> dict[str, Any]:
        v = self.vehicle
        with v.lock:
            if not v.link_up():
                raise SessionError(f"{label}: no link to the onboard computer")
            result = v.command(command, COMMAND_SENDS, ACK_TIMEOUT_S)
            if result is None:
                hint = " (is the signing key the same on both ends?)" if v.signed else ""
                raise SessionError(
                    f"{label}: no acknowledgement from the onboard computer after"
                    f" {COMMAND_SENDS} sends{hint}"
                )
            v.last_ack = {"command": label, "result": ACK_NAMES.get(result, str(result))}
            if result != mavlink.MAV_RESULT_ACCEPTED:
                why = next((e["text"] for e in reversed(v.events) if label in e["text"]), "")
                raise SessionError(f"{label} {v.last_ack['result']}" + (f": {why}" if why else ""))
            if command == CMD_START and self.rec is None:
                self._start_recording()
            return v.last_ack

    def live_command(self, action: str) -> dict[str, Any]:
        """``start`` or ``abort`` sent to the onboard computer; its COMMAND_ACK."""
        if action == "start":
            return self.live_start()
        if action == "abort":
            return self.live_abort()
        raise SessionError(f"unknown live command {action!r}")

    def live_start(self) -> dict[str, Any]:
        return self._command(CMD_START, "start")

    def live_abort(self) -> dict[str, Any]:
        return self._command(CMD_ABORT, "abort")

    # ------------------------------------------------------------------ the link thread
    def _run(self) -> None:
        next_publish = 0.0
        while not self._stop.is_set():
            try:
                next_publish = self._iterate(next_publish)
            except Exception as exc:  # never let one bad message end the live view
                self.errors += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
            self._stop.wait(0.005)

    def _iterate(self, next_publish: float) -> float:
        v = self.vehicle
        msgs = v.link.poll()
        now = time.monotonic()
        with v.lock:
            for m in msgs:
                try:
                    v.take(m, now)
                except (AttributeError, ValueError, TypeError, IndexError):
                    v.link.bad_frames += 1  # well-formed MAVLink with nonsense inside
            if (
                v.link_up()
                and len(v.params) < len(PARAM_SPECS)
                and (now - self._params_requested > 3.0)
            ):
                self._params_requested = now
                v.link.send(
                    v.link.mav.param_request_list_encode(VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID)
                )
            if v.pending:
                self._resend_unanswered(now)
            self._maybe_finish(now)
        if now >= next_publish:
            next_publish = now + self.publish_period_s
            self._publish()
        return next_publish

    # ------------------------------------------------------------------ recording
    def _start_recording(self) -> None:
        if self.log_dir is None:
            return
        self.miss_m = None
        self.vehicle.trail_vehicle, self.vehicle.trail_target = [], []
        self.rec = LiveRecording(
            Path(self.log_dir),
            foxglove=self.foxglove,
            start=SortieStart(
                scenario="live",
                law=law_name(self.vehicle.params.get("LAW")),
                seed=0,
                camera="live",
                camera_model=self.vehicle.camera_model(),
                target_diameter_m=TARGET_DIAMETER_M,
                control_rate_hz=50.0,
                gains=self.vehicle.gains,
                scenario_source="live MAVLink",
                scenario_toml="",  # a live sortie has no scenario to keep
                t0_s=self.vehicle.tel.get("t_s") or 0.0,
            ),
        )
        self._scene_reset = True

    def frame(self, t: dict[str, float | None] | None = None) -> Frame | None:
        """The sortie as the link reports it now (``t``: a telemetry message, the latest by
        default); None before the first telemetry and pose."""
        v = self.vehicle
        t = v.tel if t is None else t
        if not t or v.vehicle_p is None:
            return None
        return live_frame(
            t,
            law=self.rec.law if self.rec is not None else law_name(t.get("law")),
            camera=v.camera_model(),
            gains=v.gains,
            vehicle_p=v.vehicle_p,
            vehicle_v=v.vehicle_v,
            vehicle_q=v.vehicle_q,
            target_p=v.target_p,
            normal_accel_m_s2=v.normal_accel_m_s2,
            acquired=self.rec is not None and self.rec.acquired,
        )

    def _record(self, t: dict[str, float | None], now: float) -> None:
        """One telemetry message of the sortie being recorded: its frame, the closest approach
        (the vehicle's position the tick used against the target's last report moved on by
        its reported velocity), and the end when the onboard says so."""
        v = self.vehicle
        rec = self.rec
        if t.get("t_s") is None:
            return
        frame = self.frame(t)
        if frame is None:  # no pose yet: what the tick used stands in
            frame = live_frame(
                t,
                law=rec.law,
                camera=v.camera_model(),
                gains=v.gains,
                vehicle_p=(0.0, 0.0, 0.0),
                vehicle_v=v.vehicle_v,
                vehicle_q=v.vehicle_q,
                target_p=v.target_p,
                normal_accel_m_s2=v.normal_accel_m_s2,
                acquired=rec.acquired,
            )
        p = pose_from_values(t)[0]
        rel = None
        if v.target_p is not None and p is not None:
            dt = now - v.target_rx_s
            rel = [v.target_p[i] + v.target_v[i] * dt - p[i] for i in range(3)]
        rec.track_miss(rel)
        self.miss_m = rec.miss_m
        rec.record(frame)

    def _maybe_finish(self, now: float) -> None:
        v = self.vehicle
        if self.rec is None:
            return
        lost = self.rec.link_given_up(v.link_up(), now)
        if (
            v.onboard_state in FINISHED_STATES
            or lost
            or (
                v.onboard_state in (RuntimeState.READY.value, RuntimeState.WAITING_TARGET.value)
                and self.rec.elapsed_s > 1.0
            )
        ):
            self._finish_recording("link to the onboard lost" if lost else None)

    def _finish_recording(self, reason: str | None) -> None:
        if self.rec is None:
            return
        why = reason or next(
            (e["text"] for e in reversed(self.vehicle.events) if e["text"].startswith("finished")),
            self.vehicle.onboard_state,
        )
        self.rec.finish("LIVE_" + self.vehicle.onboard_state.upper(), why)
        self.rec = None

    @property
    def recording(self) -> dict[str, Any] | None:
        return None if self.rec is None else self.rec.status()

    # ------------------------------------------------------------------ observations
    def status(self) -> dict[str, Any]:
        v = self.vehicle
        with v.lock:
            t = v.tel
            now = time.monotonic()
            return {
                "state": "live",
                "scenario": "live",
                "law": law_name(v.params.get("LAW")),
                "seed": "—",
                "camera": "onboard",
                "speed": "1",
                "time_s": round(t.get("t_s") or 0.0, 3),
                "outcome": None,
                "miss_m": None,
                "loop_rate_hz": round(t.get("loop_rate_hz") or 0.0, 1),
                "gains_applied_time_s": v.gains_applied_time_s,
                "gains_pending": bool(v.pending),
                "real_time_ratio": 1.0,
                "scene_errors": self.scene_errors,
                "recording": self.recording,
                "replay": None,
                "dkf": None
                if not t
                else {
                    "acquired": _acquired(t),
                    "lost": bool(t.get("dkf_lost")),
                    "time_since_detection_s": t.get("dkf_since_det_s"),
                },
                "live": {
                    "url": v.url,
                    "signed": v.signed,
                    "link": "up"
                    if v.link_up()
                    else ("never heard" if v.onboard_rx_s is None else "lost"),
                    "onboard_state": v.onboard_state,
                    "fc_mode": v.fc_mode,
                    "fc_armed": v.fc_armed,
                    "fc_link": v.fc_rx_s is not None and now - v.fc_rx_s < LINK_TIMEOUT_S,
                    "target_reported": v.target_rx_s is not None
                    and now - v.target_rx_s < LINK_TIMEOUT_S,
                    "rates_hz": v.link.rates_hz(),
                    "bad_frames": v.link.bad_frames,
                    "errors": self.errors,
                    "loop_jitter_p99_ms": t.get("loop_jitter_p99_ms"),
                    "latency_ms": t.get("latency_ms"),
                    "overruns": t.get("overruns"),
                    "params_received": len(v.params),
                    "params_total": len(PARAM_SPECS),
                    "params_pending": dict(v.pending),
                    "params_sends": {n: self._param_sends[n] for n in v.pending},
                    "params_refused": dict(v.refused),
                    "last_ack": v.last_ack,
                    "events": list(v.events)[-8:],
                    "miss_m": self.miss_m,
                },
            }

    def snapshot(self) -> dict[str, Any]:
        self._publish_count += 1
        snap: dict[str, Any] = {"type": "telemetry", "status": self.status()}
        with self.vehicle.lock:
            frame = self.frame()
            if frame is not None:
                snap.update(frame_snapshot(frame, self.vehicle.camera_model(), TARGET_DIAMETER_M))
        jpeg = None if self.video is None else self.video.take_jpeg_b64()
        if jpeg is not None:  # the image panel shows the vehicle's video (overlay drawn onboard)
            snap["frame_jpeg_b64"] = jpeg
        return snap

    def _publish(self) -> None:
        v = self.vehicle
        snap = self.snapshot()
        if (
            self.scene is not None
            and v.vehicle_p is not None
            and (self._publish_count % SCENE_EVERY == 0)
        ):
            try:
                tp = v.target_p or v.vehicle_p  # no target report: nothing to draw apart
                state = SceneState(
                    v.tel.get("t_s") or 0.0,
                    tuple(v.vehicle_p),
                    tuple(v.vehicle_q),
                    tuple(tp),
                    None,
                    "",
                )
                if self._scene_reset:
                    self.scene.reset(v.camera_model(), TARGET_DIAMETER_M, state)
                    self._scene_reset = False
                self.scene.update(state, v.trail_vehicle[-600:], v.trail_target[-600:])
            except Exception:  # a viewer problem must never stop the link
                self.scene_errors += 1
        if self._on_snapshot is not None:
            self._on_snapshot(snap)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        with self.vehicle.lock:
            self._finish_recording("the ground station stopped")
        self.vehicle.link.close()
