"""The simulator session as the page sees it: the telemetry snapshot published at a fixed rate
(through the one frame -> page builder, :mod:`.snapshot`), the status, the sortie's plot series
kept for a page that (re)loads mid-sortie, and the 3D scene's updates. A mixin of
:class:`~.session.SimSession`, whose state it reads."""

from __future__ import annotations

import base64
import math
import time
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import cv2

from .numbers import fmt_num
from .scene import SceneState
from .snapshot import frame_snapshot

PUBLISH_HZ = 40.0  # telemetry snapshots per second (each viewer shows >= 30 of them)
SCENE_EVERY = 8  # update the 3D scene with every 8th snapshot (5 Hz): every scene change
# costs each viewer a WebGL render, which software GL on a laptop without GPU cannot afford
FRAME_EVERY = 5  # publish a camera frame with every 5th snapshot (8 Hz, rendered mode)
HISTORY_EVERY_S = 0.02  # the sortie's plot series kept for a page that (re)loads mid-sortie
REPLAY_MAX_X = 50.0
JPEG_QUALITY = 70

_jpeg_pool: ThreadPoolExecutor | None = None


def _jpeg_b64(frame: Any) -> str | None:
    """A camera frame (BGR) as base64 JPEG, None if OpenCV cannot encode it."""
    ok, jpg = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    return base64.b64encode(jpg.tobytes()).decode("ascii") if ok else None


class SessionView:
    """Status, snapshots, plot history and scene updates of a :class:`~.session.SimSession`."""

    _jpeg: tuple[int, Future] | None = None  # (epoch, the camera frame being encoded)
    _frame_sent_t: float | None = None  # the recorded camera frame last sent in replay

    def _encode_frame(self, frame: Any) -> None:
        """Encode a copy of the camera frame to JPEG on a worker thread: OpenCV releases the
        interpreter lock while it encodes (about 3 ms a frame, 8 times a second), so the
        simulation thread steps on meanwhile, on the other core when there is one. The
        snapshot after it is done carries it (:meth:`_take_frame`); one frame at a time."""
        global _jpeg_pool
        if self._jpeg is not None and not self._jpeg[1].done():
            return
        if _jpeg_pool is None:
            _jpeg_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="jpeg")
        self._jpeg = (self.epoch, _jpeg_pool.submit(_jpeg_b64, frame.copy()))

    def _take_frame(self) -> str | None:
        """The encoded camera frame once it is ready (None before, or if it belongs to a
        sortie no longer on screen)."""
        job = self._jpeg
        if job is None or not job[1].done():
            return None
        self._jpeg = None
        return job[1].result() if job[0] == self.epoch else None

    def _record_history(self) -> None:
        """One row of the plots' series, from the frame through the one snapshot builder."""
        sim = self.sim
        snap = frame_snapshot(sim.frame(), sim.camera_model, sim.scenario.target.diameter_m)
        e = snap["e_est_px"]
        row = {
            "t_s": snap["t"],
            "normal_accel_m_s2": snap["normal_accel_m_s2"],
            "speed_m_s": snap["speed_m_s"],
            "normal_vel_m_s": snap["normal_vel_m_s"],
            "e_x_px": None if e is None else float(e[0]),
            "e_y_px": None if e is None else float(e[1]),
            "range_m": snap["range_m"],
        }
        with self._lock:
            for k, val in row.items():
                self.history[k].append(val)

    def series(self) -> dict[str, Any]:
        """The sortie on screen so far, in the shape of a recorded sortie's series."""
        with self._lock:
            h = {k: list(v) for k, v in self.history.items()}
        return {"t_s": h.pop("t_s"), "columns": h, "events": list(self.events)}

    @property
    def recording(self) -> dict[str, Any] | None:
        rec = None if self.sim is None else self.recorder
        if rec is None or (rec.path is None and rec.error is None):
            return None
        name = None if rec.path is None else rec.path.name  # None: no file could be made
        return {"file": name, "error": rec.error, "closed": rec.closed}

    def _publish(self, force: bool = False) -> None:
        snap = self.snapshot()
        scene_due = force or self._publish_count % SCENE_EVERY == 0 or self.state != "running"
        if self.scene is not None and self.replay is not None and scene_due:
            try:
                self.scene.update(
                    self.replay.scene_state(self.replay_t), *self.replay.trails(self.replay_t)
                )
            except Exception as exc:  # a viewer problem must never stop the replay
                self.scene_errors += 1
                self.last_scene_error = f"{type(exc).__name__}: {exc}"
        elif self.scene is not None and self.sim is not None and scene_due:
            try:
                self.scene.update(self._scene_state(), self._trail_vehicle, self._trail_target)
            except Exception as exc:  # a viewer problem must never stop the sortie
                self.scene_errors += 1
                self.last_scene_error = f"{type(exc).__name__}: {exc}"
        if self._on_snapshot is not None:
            self._on_snapshot(snap)

    def _scene_state(self) -> SceneState:
        sim = self.sim
        closest = None
        if sim.done:
            tp = sim.target.p
            closest = tuple(tp[i] - sim.closest_rel_m[i] for i in range(3))
        return SceneState(
            sim.time_s,
            tuple(sim.vehicle.p),
            tuple(sim.vehicle.q),
            tuple(sim.target.p),
            closest,
            f"{sim.outcome.value} miss {fmt_num(sim.miss_m)} m" if sim.done else "",
        )

    # ------------------------------------------------------------------ observations
    def replay_speed(self) -> float:
        """Recorded seconds played per wall second ("max" plays at REPLAY_MAX_X)."""
        return REPLAY_MAX_X if math.isinf(self.speed) else self.speed

    def loop_rate_hz(self) -> float:
        """Control ticks run per wall-clock second, over the last second."""
        if self.state != "running":
            return 0.0
        now = time.perf_counter()
        # read-only here: status() is also called from the web server's thread
        recent = sum(1 for t in tuple(self._tick_walls) if t >= now - 1.0)
        return recent / min(1.0, max(now - self._anchor_wall, 1e-3))

    def status(self) -> dict[str, Any]:
        sim = self.sim
        out: dict[str, Any] = {
            "state": self.state,
            "scenario": self.config.scenario.name,
            "law": self.config.law,
            "seed": self.config.seed,
            "camera": self.config.camera,
            # the state-estimate error profile flown ("ideal": ideal sensors, shown as such)
            "profile": None if sim is None else sim.profile,
            "speed": self.config.speed,
            "time_s": 0.0 if sim is None else round(sim.time_s, 4),
            "outcome": None,
            "miss_m": None,
            "loop_rate_hz": round(self.loop_rate_hz(), 1),
            "gains_applied_time_s": self.gains_applied_time_s,
            "gains_pending": self._gains_pending is not None,
            "gains_source": self.gains_source,
            "gains_edited": self.gains_edited(),
            "gains_note": self.gains_note,
            "epoch": self.epoch,
            "compare": None if self.compare is None else self.compare.describe(),
            "real_time_ratio": (self.run_sim_s / self.run_wall_s) if self.run_wall_s > 0 else None,
            "scene_errors": self.scene_errors,
            "recording": self.recording,
            "replay": None
            if self.replay is None
            else {
                "file": self.replay.name,
                "t_s": round(self.replay_t, 4),
                "duration_s": round(self.replay.duration_s, 4),
                "playing": self.replay_playing,
                "speed_x": self.replay_speed(),
                "closest_time_s": round(self.replay.closest_time_s, 4),
                "status": self.replay.info.status,
                "compare": None if self.compare is None else self.compare.name,
            },
        }
        rp = self.replay
        if rp is not None:  # what is on screen is the recorded sortie
            at_end = self.replay_t >= rp.duration_s - 1e-6
            out.update(
                scenario=rp.info.scenario,
                law=rp.info.law,
                seed=rp.info.seed,
                camera=rp.info.camera,
                profile=rp.info.metadata.get("sortie", {}).get("estimate_profile") or None,
                time_s=round(self.replay_t, 4),
                outcome=rp.info.outcome if at_end else None,
                miss_m=rp.info.miss_m if at_end else None,
                # the replayed sortie's gains, not the operator's: those that differ from the
                # defaults
                gains_source=f"recorded in {rp.name}",
                gains_edited={},
                gains_note=None,
                gains_recorded=rp.gains_not_default(),
            )
        if sim is not None:
            dkf = sim.loop.dkf
            est = dkf.estimate()
            out["dkf"] = {
                "acquired": sim.loop.acquired,
                "lost": dkf.lost(sim.time_s),
                "time_since_detection_s": None
                if est is None
                else round(est.time_since_detection_s, 3),
            }
            if sim.done:
                out["outcome"] = sim.outcome.value
                out["miss_m"] = sim.miss_m  # rounded where shown (numbers.py)
                out["intercept_time_s"] = round(sim.closest_time_s, 3)
        return out

    def snapshot(self) -> dict[str, Any]:
        self._publish_count += 1
        snap: dict[str, Any] = {"type": "telemetry", "status": self.status()}
        snap["events"] = self.events if self.replay is None else self.replay.timeline
        if self.replay is not None:
            rp = self.replay
            snap.update(
                frame_snapshot(rp.frame(self.replay_t), rp.camera, rp.diameter_m, t_s=self.replay_t)
            )
            # the recorded camera frame at the cursor (the last one at or before it, with its
            # time; None: no frame there, the page shows none), sent after a seek and, while
            # playing, each time the cursor reaches another frame: the image follows the cursor
            if self._force_frame or (
                self.replay_playing and rp.frame_time_at(self.replay_t) != self._frame_sent_t
            ):
                self._force_frame = False
                frame_t, frame = rp.frame_at(self.replay_t)
                self._frame_sent_t = frame_t
                snap["frame_t_s"] = frame_t
                if frame:
                    snap["frame_jpeg_b64"] = frame
            return snap
        sim = self.sim
        if sim is None:
            return snap
        snap.update(frame_snapshot(sim.frame(), sim.camera_model, sim.scenario.target.diameter_m))
        frame = sim.camera.last_frame
        if frame is not None and (self._force_frame or self._publish_count % FRAME_EVERY == 0):
            self._force_frame = False
            self._encode_frame(frame)
        jpeg = self._take_frame()
        if jpeg is not None:
            snap["frame_jpeg_b64"] = jpeg
        return snap


def _empty_history() -> dict[str, list]:
    keys = ("t_s", "normal_accel_m_s2", "speed_m_s", "normal_vel_m_s", "e_x_px", "e_y_px")
    return {k: [] for k in (*keys, "range_m")}
