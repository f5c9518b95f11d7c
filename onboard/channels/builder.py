"""A sortie's messages on its channels (:mod:`.schemas`), built from the frames a producer
tells: :class:`ChannelBuilder` is a sortie observer (:mod:`onboard.frames`) writing into a
*sink*: the ground station's MCAP file (:class:`~groundstation.recording.writer.
SortieRecorder`, a ChannelBuilder that opens one) or Foxglove live (:mod:`.live`, in
``groundstation serve --foxglove`` and ``onboard run --foxglove``). One definition of every
message, wherever it goes.

The observer's thread gathers each fast message's numbers and hands them to the sink, which
encodes them (:mod:`.encode`) where it writes; the slow channels are encoded here. A sink's
failure (:class:`OSError`: a full disk) ends the builder with a clear message in ``error``
and never the sortie. Log times are on the sortie's own clock.

Rates: the vehicle's pose and /control every ``record_every`` control ticks (20 Hz by
default: recording must cost a sortie at most about a tenth of its simulation time, and
every message costs a few microseconds); the target's pose, /tf (the vehicle's pose again,
which Foxglove interpolates) and /dkf at half that; /scene at 1 Hz;
image annotations at every ``annotate_every``-th camera capture (10 Hz) and the frames
themselves at every ``frame_every``-th (5 Hz: a JPEG encode costs as much as rendering the
frame); /gains and /events as they happen.

A sink has ``add(channel index, log ns, bytes)``, ``add_many(log ns, [(channel index,
encoder, payload)])``, ``metadata(name, dict)``, ``attachment(name, media type, bytes)``,
``started()``, ``finish(outcome dict)`` and ``abandon()``.
"""

from __future__ import annotations

import base64
import json
import math
from datetime import datetime, timezone
from typing import Any

import cv2
import numpy as np

from .. import __version__ as onboard_version
from ..datatypes import LoopMode
from ..frames import Frame, SortieStart
from . import encode as enc
from .schemas import CHANNELS

# the loop's track-loss ladder (onboard/control/reacquire.py), one event as each begins
_LADDER = {
    LoopMode.COAST: "no detection: coasting on the prediction",
    LoopMode.REACQUIRE: "re-acquiring: yawing toward the predicted target, slowing",
    LoopMode.SEARCH: "searching for the target",
}
LEVEL = {"debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}


def _ns(t_s: float) -> int:
    return round(t_s * 1e9)


def _stamp(t_s: float) -> dict[str, int]:
    ns = _ns(t_s)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


class ChannelBuilder:
    """Builds the sortie it observes into ``sink`` (see the module docstring)."""

    def __init__(
        self,
        sink=None,
        record_every: int = 5,
        annotate_every: int = 3,
        frame_every: int = 6,
    ) -> None:
        self._given_sink = sink
        self.path = None  # a file's path (the recorder's), named in errors
        self.info: SortieStart | None = None
        self._t0 = 0.0
        self._last: Frame | None = None
        self.record_every = record_every
        self.annotate_every = annotate_every
        self.frame_every = frame_every
        self._frames = 0
        self.error: str | None = None
        self.closed = False
        self._tick = 0
        self._last_gains = None
        self._was_tracking = False
        self._was_lost = False
        self._last_mode: LoopMode | None = None
        self._ever_tracked = False
        self._guard_trips = 0
        self._sink = None
        self._joined = None  # the sink's "a client just subscribed" test (Foxglove live)
        self._ch = {topic: i for i, (topic, _) in enumerate(CHANNELS)}

    software = f"peregrine onboard {onboard_version}"  # the "software_version" metadata

    def _open_sink(self, info: SortieStart):
        """The sink for this sortie (None: it could not be opened, ``error`` says why)."""
        return self._given_sink

    def start(self, info: SortieStart) -> None:
        """Write what the sortie is (metadata, scenario, calibration)."""
        self.info = info
        self._t0 = info.t0_s
        self._sink = self._open_sink(info)
        if self._sink is None:
            return
        try:
            cam = info.camera_model
            R = cam.R_BC
            q = _quat_xyzw(R)
            self._tf_camera = (
                '{"timestamp":{"sec":0,"nsec":0},"parent_frame_id":"body",'
                '"child_frame_id":"camera","translation":{"x":0,"y":0,"z":0},'
                f'"rotation":{{"x":{q[0]:.6f},"y":{q[1]:.6f},"z":{q[2]:.6f},"w":{q[3]:.6f}}}}}'
            )
            self._sink.metadata(
                "sortie",
                {
                    "scenario": info.scenario,
                    "law": info.law,
                    "seed": str(info.seed),
                    "camera": info.camera,
                    "gains": json.dumps(info.gains.to_dict()),
                    "software_version": self.software,
                    "scenario_source": info.scenario_source,
                    "recorded_at_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                    "record_rate_hz": str(info.control_rate_hz / self.record_every),
                    "estimate_profile": info.estimate_profile,
                },
            )
            self._sink.attachment("scenario.toml", "application/toml", info.scenario_toml.encode())
            self._calibration(0.0)
            self.event(
                0.0,
                "info",
                f"sortie start: {info.scenario}, law {info.law}, "
                f"seed {info.seed}, camera {info.camera}"
                + (f", estimate profile {info.estimate_profile}" if info.estimate_profile else "")
                + (" (ideal sensors: analysis only)" if info.estimate_profile == "ideal" else ""),
            )
            self._sink.started()
            self._joined = getattr(self._sink, "joined", None)
        except OSError as exc:
            self._fail(exc)

    # ---------------------------------------------------------------- plumbing
    def _fail(self, exc: BaseException) -> None:
        self.error = f"recording stopped: {type(exc).__name__}: {exc} ({self.path})"
        self.closed = True
        if self._sink is not None:
            self._sink.abandon()

    def _put(self, topic: str, t_s: float, data: bytes) -> None:
        if self.closed:
            return
        try:
            self._sink.add(self._ch[topic], _ns(t_s), data)
        except OSError as exc:
            self._fail(exc)

    def _put_many(self, ns: int, items: list[tuple[int, bytes]]) -> None:
        """Several messages at one log time (channel id, data): the record tick's hot path."""
        try:
            self._sink.add_many(ns, items)
        except OSError as exc:
            self._fail(exc)

    def _json(self, topic: str, t_s: float, obj: dict) -> None:
        self._put(topic, t_s, json.dumps(obj, separators=(",", ":")).encode())

    # ---------------------------------------------------------------- channels
    def event(self, t_s: float, level: str, message: str) -> None:
        self._json(
            "/events",
            t_s,
            {
                "timestamp": _stamp(t_s),
                "level": LEVEL[level],
                "message": message,
                "name": "peregrine",
                "file": "",
                "line": 0,
            },
        )

    def republish(self) -> None:
        """The calibration and the gains in force again, at the last frame's time: a Foxglove
        client that subscribes mid-sortie gets them too (they are sent once otherwise; the
        sink's ``joined()`` says when, checked at record ticks)."""
        if self.closed or self.info is None or self._sink is None:
            return
        t_s = 0.0 if self._last is None else max(self._last.time_s - self._t0, 0.0)
        self._calibration(t_s)
        if self._last_gains is not None:
            self._json("/gains", t_s, self._last_gains.to_dict())

    def _calibration(self, t_s: float) -> None:
        cam = self.info.camera_model
        f, cu, cv = cam.f_px, cam.cu_px, cam.cv_px
        self._json(
            "/camera/calibration",
            t_s,
            {
                "timestamp": _stamp(t_s),
                "frame_id": "camera",
                "width": cam.width_px,
                "height": cam.height_px,
                "distortion_model": "plumb_bob",
                "D": [*cam.distortion, 0],  # k1, k2, p1, p2, k3
                "K": [f, 0, cu, 0, f, cv, 0, 0, 1],
                "R": [1, 0, 0, 0, 1, 0, 0, 0, 1],
                "P": [f, 0, cu, 0, 0, f, cv, 0, 0, 0, 1, 0],
            },
        )

    def frame(self, frame: Frame) -> None:
        """One control tick: /gains and /events as they change, the fast channels at their
        rates (see the module docstring)."""
        if self.closed or frame.telemetry is None:
            return
        t_s = max(frame.time_s - self._t0, 0.0)
        for ev in frame.events:
            self.event(max(ev.time_s - self._t0, 0.0), ev.level, ev.message)
        if self._last is not None and frame.time_s <= self._last.time_s:
            return  # a frame seen already (re-sent to carry late events)
        self._last = frame
        tel = frame.telemetry
        gains = frame.gains
        if gains is not self._last_gains:
            first = self._last_gains is None
            self._last_gains = gains
            self._json("/gains", t_s, gains.to_dict())
            if not first:
                self.event(
                    t_s,
                    "info",
                    "gains changed: " + ", ".join(f"{k}={v:g}" for k, v in gains.to_dict().items()),
                )
        tracking = tel.mode is LoopMode.TRACKING
        if tracking and not self._was_tracking:
            again = self._ever_tracked
            self.event(t_s, "info", "target reacquired" if again else "target acquired")
            self._ever_tracked = True
        if tel.mode is LoopMode.LOST and not self._was_lost:
            self.event(t_s, "warning", "target lost: braking and holding")
        if tel.mode in _LADDER and tel.mode is not self._last_mode:
            self.event(t_s, "warning" if tel.mode is LoopMode.SEARCH else "info", _LADDER[tel.mode])
        self._was_tracking, self._was_lost = tracking, tel.mode is LoopMode.LOST
        self._last_mode = tel.mode
        if frame.guard_trips != self._guard_trips:
            self._guard_trips = frame.guard_trips
            self.event(t_s, "error", "output guard: non-finite command replaced by hover")
        self._tick += 1
        if (self._tick - 1) % self.record_every:
            return
        if self._joined is not None and self._joined():
            self.republish()
        ns = _ns(t_s)
        sec, nsec = divmod(ns, 1_000_000_000)
        ch = self._ch
        p, q = frame.vehicle_p_enu_m, frame.vehicle_q_wxyz
        pose = (sec, nsec, p[0], p[1], p[2], q[1], q[2], q[3], q[0])
        tp = frame.target_p_enu_m  # None: a live target that does not report its position
        items = [(ch["/world/vehicle"], enc.POSE, pose)]
        half = (self._tick - 1) % (2 * self.record_every) == 0
        if half:  # the target, /tf (the vehicle pose again) and /dkf at half rate
            if tp is not None:
                items.append(
                    (ch["/world/target"], enc.POSE, (sec, nsec, tp[0], tp[1], tp[2], 0, 0, 0, 1))
                )
            items.append((ch["/tf"], enc.TF, (*pose, self._tf_camera)))
        det = frame.detection
        rng = None
        if tp is not None:
            rx, ry, rz = tp[0] - p[0], tp[1] - p[1], tp[2] - p[2]
            rng = math.sqrt(rx * rx + ry * ry + rz * rz)
        cmd = tel.command
        items.append(
            (
                ch["/control"],
                enc.CONTROL,
                (
                    t_s,
                    tel.mode.value,
                    tel.law,
                    tel.los_elev_rad,
                    tel.los_azim_rad,
                    tel.vel_elev_rad,
                    tel.vel_azim_rad,
                    tel.accel_desired_enu_m_s2.tolist(),
                    tel.accel_normal_desired_m_s2,
                    frame.normal_accel_m_s2,
                    cmd.body_rates_flu_rad_s.tolist(),
                    cmd.thrust_normalised,
                    tel.yaw_rate_cmd_rad_s,
                    tel.e_est_px,
                    tel.e_rate_est_px_s,
                    frame.speed_m_s,
                    rng,
                    frame.vehicle_v_enu_m_s,
                    None if det is None else self.info.camera_model.error_px(*det.center_px),
                    None if det is None else det.capture_time_s - self._t0,
                    tel.speed_cap_m_s,
                ),
            )
        )
        if half:
            items.append(
                (
                    ch["/dkf"],
                    enc.DKF,
                    (
                        t_s,
                        frame.dkf_state_px,
                        frame.dkf_cov_diag,
                        frame.acquired,
                        tel.dkf_lost,
                        tel.dkf_time_since_detection_s,
                        tel.self_cal,
                        tel.target_accel_enu_m_s2,
                        tel.motion_model_probs,
                        tel.target_turn_rate_rad_s,
                    ),
                )
            )
        self._put_many(ns, items)
        if (self._tick - 1) % (self.record_every * 20) == 0 and tp is not None:  # /scene
            self._scene(t_s, p, tp)

    def _scene(self, t_s: float, p, tp) -> None:
        stamp = _stamp(t_s)
        d = self.info.target_diameter_m
        ident = {"x": 0, "y": 0, "z": 0, "w": 1}
        self._json(
            "/scene",
            t_s,
            {
                "deletions": [],
                "entities": [
                    {
                        "timestamp": stamp,
                        "frame_id": "world",
                        "id": "engagement",
                        "lifetime": {"sec": 0, "nsec": 0},
                        "frame_locked": False,
                        "metadata": [],
                        "arrows": [],
                        "cubes": [],
                        "cylinders": [],
                        "triangles": [],
                        "texts": [],
                        "models": [],
                        "spheres": [
                            {
                                "pose": {
                                    "position": {"x": tp[0], "y": tp[1], "z": tp[2]},
                                    "orientation": ident,
                                },
                                "size": {"x": d, "y": d, "z": d},
                                "color": {"r": 0.9, "g": 0.1, "b": 0.1, "a": 1.0},
                            }
                        ],
                        "lines": [
                            {
                                "type": 1,
                                "pose": {
                                    "position": {"x": 0, "y": 0, "z": 0},
                                    "orientation": ident,
                                },
                                "thickness": 2.0,
                                "scale_invariant": True,
                                "points": [
                                    {"x": p[0], "y": p[1], "z": p[2]},
                                    {"x": tp[0], "y": tp[1], "z": tp[2]},
                                ],
                                "color": {"r": 1.0, "g": 0.67, "b": 0.0, "a": 1.0},
                                "colors": [],
                                "indices": [],
                            }
                        ],
                    }
                ],
            },
        )

    def image(self, time_s: float, frame: np.ndarray | None) -> None:
        """A camera capture at ``time_s``: the frame (rendered mode) and the annotations
        (image centre, DKF estimate, latest raw detection as of the last control tick), each at
        its own fraction of captures."""
        if self.closed:
            return
        t_s = max(time_s - self._t0, 0.0)
        self._frames += 1
        k = self._frames - 1
        if k % self.annotate_every and k % self.frame_every:
            return
        sec, nsec = divmod(_ns(t_s), 1_000_000_000)
        if frame is not None and k % self.frame_every == 0:
            ok, jpg = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 80])
            if ok:
                self._put(
                    "/camera/image",
                    t_s,
                    (
                        '{"timestamp":{"sec":%d,"nsec":%d},"frame_id":"camera","format":"jpeg",'
                        '"data":"%s"}'
                        % (sec, nsec, base64.b64encode(jpg.tobytes()).decode("ascii"))
                    ).encode(),
                )
        if k % self.annotate_every:
            return
        cam = self.info.camera_model
        ts = '{"sec":%d,"nsec":%d}' % (sec, nsec)
        clear = '{"r":0,"g":0,"b":0,"a":0}'
        circles = [
            '{"timestamp":%s,"position":{"x":%.2f,"y":%.2f},"diameter":12,"thickness":2,'
            '"fill_color":%s,"outline_color":{"r":1,"g":1,"b":1,"a":1}}'
            % (ts, cam.cu_px, cam.cv_px, clear)
        ]
        last = self._last
        tel = None if last is None else last.telemetry
        if tel is not None and tel.e_est_px is not None:
            circles.append(
                '{"timestamp":%s,"position":{"x":%.2f,"y":%.2f},"diameter":18,"thickness":2.5,'
                '"fill_color":%s,"outline_color":{"r":0.1,"g":0.76,"b":0.36,"a":1}}'
                % (ts, cam.cu_px + tel.e_est_px[0], cam.cv_px + tel.e_est_px[1], clear)
            )
        points = ""
        det = None if last is None else last.detection
        if det is not None:
            u, v = det.center_px
            points = (
                '{"timestamp":%s,"type":2,"thickness":2,"points":[{"x":%.2f,"y":%.2f},'
                '{"x":%.2f,"y":%.2f},{"x":%.2f,"y":%.2f},{"x":%.2f,"y":%.2f}],'
                '"outline_color":{"r":1,"g":0.62,"b":0.11,"a":1},"outline_colors":[],'
                '"fill_color":%s}'
                % (ts, u - 7, v - 7, u + 7, v - 7, u + 7, v + 7, u - 7, v + 7, clear)
            )
        self._put(
            "/camera/annotations",
            t_s,
            ('{"circles":[%s],"points":[%s],"texts":[]}' % (",".join(circles), points)).encode(),
        )

    def finish(
        self, time_s: float, summary: dict[str, Any] | None, reason: str | None = None
    ) -> None:
        """Close the sink (a file) with the outcome (or the reason the sortie stopped early)."""
        if self.closed or self._sink is None:
            return
        t_end = time_s - self._t0
        if summary is not None:
            level = "info" if summary.get("outcome") == "HIT" else "warning"
            miss = summary.get("miss_m")
            self.event(
                t_end,
                level,
                f"outcome {summary['outcome']}: miss "
                + ("unknown" if miss is None else f"{miss:.3f} m")
                + f" at t = {summary['intercept_time_s']:.2f} s",
            )
        else:
            self.event(t_end, "warning", f"sortie stopped early: {reason or 'no outcome'}")
        try:
            self._sink.finish(
                {
                    k: json.dumps(v)
                    for k, v in (
                        summary or {"outcome": "INCOMPLETE", "reason": reason or "stopped"}
                    ).items()
                }
            )
            self.closed = True
        except OSError as exc:
            self._fail(exc)


def _quat_xyzw(R: np.ndarray) -> tuple[float, float, float, float]:
    from ..geometry import rotmat_to_quat

    w, x, y, z = rotmat_to_quat(R)
    return float(x), float(y), float(z), float(w)
