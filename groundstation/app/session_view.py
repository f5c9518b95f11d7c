"""The simulator session as the page sees it: the telemetry snapshot published at a fixed rate
(through the one frame -> page builder, :mod:`.snapshot`), the status, the sortie's plot series
kept for a page that (re)loads mid-sortie, and the 3D scene's updates. A part of
:class:`~.session.SimSession` (``session.view``), which it reads: the sortie flying, the
recorded one replayed (``session.replays``), the gains and the pace."""

from __future__ import annotations

import base64
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TYPE_CHECKING, Any

from .numbers import fmt_num
from .scene import SceneState
from .snapshot import frame_snapshot

if TYPE_CHECKING:
    from onboard.gains import Gains

    from .session import SimSession

PUBLISH_HZ = 40.0  # telemetry snapshots per second (each viewer shows >= 30 of them)
SCENE_EVERY = 8  # update the 3D scene with every 8th snapshot (5 Hz): every scene change
# costs each viewer a WebGL render, which software GL on a laptop without GPU cannot afford
FRAME_EVERY = 5  # publish a camera frame with every 5th snapshot (8 Hz, rendered mode)
HISTORY_EVERY_S = 0.02  # the sortie's plot series kept for a page that (re)loads mid-sortie
JPEG_QUALITY = 70

_jpeg_pool: ThreadPoolExecutor | None = None


def _jpeg_b64(frame: Any) -> str | None:
    """A camera frame (BGR) as base64 JPEG, None if OpenCV cannot encode it."""
    import cv2  # only a rendered camera has frames: not imported when the server starts

    ok, jpg = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    return base64.b64encode(jpg.tobytes()).decode("ascii") if ok else None


class SessionView:
    """Status, snapshots, plot history and scene updates of a :class:`~.session.SimSession`."""

    def __init__(self, session: SimSession) -> None:
        self.session = session
        self.history: dict[str, list] = _empty_history()
        self._last_history_t = -1.0
        self._jpeg: tuple[int, Future] | None = None  # (epoch, the camera frame being encoded)
        self.force_frame = False  # the next snapshot carries the camera frame
        self._encoded_src: Any = None  # the last camera frame encoded
        self._frame_sent_t: float | None = None  # the recorded camera frame last sent in replay
        self.publish_count = 0
        self.scene_errors = 0
        self.last_scene_error: str | None = None
        self._gains_edited: tuple[Gains, Gains, dict[str, list[float]]] | None = None

    def gains_edited(self) -> dict[str, list[float]]:
        """The operator's edits: name -> [base value, value in force]. Worked out again only
        when either set changes (they are frozen): every snapshot's status carries it, and
        two ``to_dict`` calls cost the simulation thread more than the rest of the snapshot."""
        base_gains, gains = self.session.gains_base, self.session.gains
        cached = self._gains_edited
        if cached is None or cached[0] is not base_gains or cached[1] is not gains:
            base, now = base_gains.to_dict(), gains.to_dict()
            edited = {k: [base[k], v] for k, v in now.items() if v != base[k]}
            cached = self._gains_edited = (base_gains, gains, edited)
        return {k: list(v) for k, v in cached[2].items()}

    def request_frame(self) -> None:
        """Send a camera frame with the next snapshot (a page has just (re)connected)."""
        self.force_frame = True

    def new_sortie(self) -> None:
        """Another sortie on screen: its plot series start empty."""
        self.history = _empty_history()
        self._last_history_t = -1.0

    def encode_frame(self, frame: Any) -> None:
        """Encode a copy of the camera frame to JPEG on a worker thread: OpenCV releases the
        interpreter lock while it encodes (about 3 ms a frame, 8 times a second), so the
        simulation thread steps on meanwhile, on the other core when there is one. The
        snapshot after it is done carries it (:meth:`_take_frame`); one frame at a time."""
        global _jpeg_pool
        if self._jpeg is not None and not self._jpeg[1].done():
            return
        if _jpeg_pool is None:
            _jpeg_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="jpeg")
        self._jpeg = (self.session.epoch, _jpeg_pool.submit(_jpeg_b64, frame.copy()))

    def _take_frame(self) -> str | None:
        """The encoded camera frame once it is ready (None before, or if it belongs to a
        sortie no longer on screen)."""
        job = self._jpeg
        if job is None or not job[1].done():
            return None
        self._jpeg = None
        return job[1].result() if job[0] == self.session.epoch else None

    def record_history(self) -> None:
        """One row of the plots' series every HISTORY_EVERY_S of the sortie, from the frame
        through the one snapshot builder."""
        sim = self.session.sim
        if sim.time_s - self._last_history_t < HISTORY_EVERY_S - 1e-9:
            return
        self._last_history_t = sim.time_s
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
        with self.session.lock:
            for k, val in row.items():
                self.history[k].append(val)

    def series(self) -> dict[str, Any]:
        """The sortie on screen so far, in the shape of a recorded sortie's series."""
        with self.session.lock:
            h = {k: list(v) for k, v in self.history.items()}
        return {"t_s": h.pop("t_s"), "columns": h, "events": list(self.session.events)}

    @property
    def recording(self) -> dict[str, Any] | None:
        s = self.session
        rec = None if s.sim is None else s.recorder
        if rec is None or (rec.path is None and rec.error is None):
            return None
        name = None if rec.path is None else rec.path.name  # None: no file could be made
        return {"file": name, "error": rec.error, "closed": rec.closed}

    def publish(self, force: bool = False) -> None:
        """Hand the snapshot to the subscribers and, every SCENE_EVERY (or ``force``), update
        the 3D scene."""
        s, rp = self.session, self.session.replays
        snap = self.snapshot()
        scene_due = force or self.publish_count % SCENE_EVERY == 0 or s.state != "running"
        if s.scene is not None and rp.player is not None and scene_due:
            try:
                s.scene.update(rp.player.scene_state(rp.t_s), *rp.player.trails(rp.t_s))
            except Exception as exc:  # a viewer problem must never stop the replay
                self.scene_errors += 1
                self.last_scene_error = f"{type(exc).__name__}: {exc}"
        elif s.scene is not None and s.sim is not None and scene_due:
            try:
                s.scene.update(self.scene_state(), s._trail_vehicle, s._trail_target)
            except Exception as exc:  # a viewer problem must never stop the sortie
                self.scene_errors += 1
                self.last_scene_error = f"{type(exc).__name__}: {exc}"
        if s.on_snapshot is not None:
            s.on_snapshot(snap)

    def scene_state(self) -> SceneState:
        """The sortie flying as the 3D view shows it."""
        sim = self.session.sim
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
    def status(self) -> dict[str, Any]:
        s = self.session
        sim, rp, replays = s.sim, s.replays.player, s.replays
        compare = replays.compare
        out: dict[str, Any] = {
            "state": s.state,
            "scenario": s.config.scenario.name,
            "law": s.config.law,
            "seed": s.config.seed,
            "camera": s.config.camera,
            # the state-estimate error profile flown ("ideal": ideal sensors, shown as such)
            "profile": None if sim is None else sim.profile,
            "speed": s.config.speed,
            "time_s": 0.0 if sim is None else round(sim.time_s, 4),
            "outcome": None,
            "miss_m": None,
            "loop_rate_hz": round(s.loop_rate_hz(), 1),
            "gains_applied_time_s": s.gains_applied_time_s,
            "gains_pending": s.gains_pending(),
            "gains_source": s.gains_source,
            "gains_edited": self.gains_edited(),
            "gains_note": s.gains_note,
            "epoch": s.epoch,
            "compare": None if compare is None else compare.describe(),
            "real_time_ratio": (s.run_sim_s / s.run_wall_s) if s.run_wall_s > 0 else None,
            "scene_errors": self.scene_errors,
            "recording": self.recording,
            "replay": None
            if rp is None
            else {
                "file": rp.name,
                "t_s": round(replays.t_s, 4),
                "duration_s": round(rp.duration_s, 4),
                "playing": replays.playing,
                "speed_x": replays.speed_x(),
                "closest_time_s": round(rp.closest_time_s, 4),
                "status": rp.info.status,
                "compare": None if compare is None else compare.name,
            },
        }
        if rp is not None:  # what is on screen is the recorded sortie
            at_end = replays.t_s >= rp.duration_s - 1e-6
            out.update(
                scenario=rp.info.scenario,
                law=rp.info.law,
                seed=rp.info.seed,
                camera=rp.info.camera,
                profile=rp.info.metadata.get("sortie", {}).get("estimate_profile") or None,
                time_s=round(replays.t_s, 4),
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
                "acquired": sim.loop.ladder.acquired,
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
        s, replays = self.session, self.session.replays
        self.publish_count += 1
        snap: dict[str, Any] = {"type": "telemetry", "status": self.status()}
        rp = replays.player
        snap["events"] = s.events if rp is None else rp.timeline
        if rp is not None:
            t = replays.t_s
            snap.update(frame_snapshot(rp.frame(t), rp.camera, rp.diameter_m, t_s=t))
            # the recorded camera frame at the cursor (the last one at or before it, with its
            # time; None: no frame there, the page shows none), sent after a seek and, while
            # playing, each time the cursor reaches another frame: the image follows the cursor
            if self.force_frame or (replays.playing and rp.frame_time_at(t) != self._frame_sent_t):
                self.force_frame = False
                frame_t, frame = rp.frame_at(t)
                self._frame_sent_t = frame_t
                snap["frame_t_s"] = frame_t
                if frame:
                    snap["frame_jpeg_b64"] = frame
            return snap
        sim = s.sim
        if sim is None:
            return snap
        snap.update(frame_snapshot(sim.frame(), sim.camera_model, sim.scenario.target.diameter_m))
        frame = sim.camera.last_frame  # a new array each capture
        due = self.publish_count % FRAME_EVERY == 0 and frame is not self._encoded_src
        if frame is not None and (self.force_frame or due):
            self.force_frame = False
            self._encoded_src = frame  # a paused or finished sortie's is not encoded again
            self.encode_frame(frame)
        jpeg = self._take_frame()
        if jpeg is not None:
            snap["frame_jpeg_b64"] = jpeg
        return snap


def _empty_history() -> dict[str, list]:
    keys = ("t_s", "normal_accel_m_s2", "speed_m_s", "normal_vel_m_s", "e_x_px", "e_y_px")
    return {k: [] for k in (*keys, "range_m")}
