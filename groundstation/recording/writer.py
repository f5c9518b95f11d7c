"""Writes one sortie to ``logs/<UTC time>_<scenario>_<law>.mcap`` while it flies.

Chunked and indexed MCAP (zstd), JSON messages with Foxglove's well-known schemas, log times
on the sortie's own clock. The file is created exclusively (an existing one is never
overwritten) and each full chunk goes to disk as it is written, so a crash leaves a readable
file up to the last chunk. A write error (a full disk) ends the recording with a clear
message in ``error`` and never the sortie.

Rates: the vehicle's pose and /control every ``record_every`` control ticks (20 Hz by
default: recording must cost a sortie at most about a tenth of its simulation time, and
every message costs a few microseconds); the target's pose, /tf (the vehicle's pose again,
which Foxglove interpolates) and /dkf at half that; /scene at 1 Hz;
image annotations at every ``annotate_every``-th camera capture (10 Hz) and the frames
themselves at every ``frame_every``-th (5 Hz: a JPEG encode costs as much as rendering the
frame); /gains and /events as they happen.
"""

from __future__ import annotations

import base64
import contextlib
import json
import math
import re
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from mcap.writer import CompressionType, Writer

from onboard import __version__ as onboard_version
from onboard.datatypes import ControlTelemetry, LoopMode

from .. import __version__ as gs_version
from .schemas import CHANNELS, schema_bytes

CHUNK_BYTES = 256 * 1024
LEVEL = {"debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}

_POSE = (
    '{"timestamp":{"sec":%d,"nsec":%d},"frame_id":"world","pose":{"position":'
    '{"x":%.4f,"y":%.4f,"z":%.4f},"orientation":{"x":%.6f,"y":%.6f,"z":%.6f,"w":%.6f}}}'
)
_TF = (
    '{"transforms":[{"timestamp":{"sec":%d,"nsec":%d},"parent_frame_id":"world",'
    '"child_frame_id":"body","translation":{"x":%.4f,"y":%.4f,"z":%.4f},'
    '"rotation":{"x":%.6f,"y":%.6f,"z":%.6f,"w":%.6f}},%s]}'
)


def _ns(t_s: float) -> int:
    return round(t_s * 1e9)


def _stamp(t_s: float) -> dict[str, int]:
    ns = _ns(t_s)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _js(x: float | None) -> str:
    """A number as JSON (null when missing or not finite)."""
    return "null" if x is None or not math.isfinite(x) else "%.6g" % x


def _js2(pair) -> str:
    return "null" if pair is None else "[%.3f,%.3f]" % (pair[0], pair[1])


def log_name(scenario: str, law: str, when: datetime | None = None) -> str:
    when = when or datetime.now(timezone.utc)
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "-", scenario).strip("-") or "sortie"
    return f"{when:%Y%m%dT%H%M%SZ}_{safe}_{law}.mcap"


def open_new_log(directory: Path, scenario: str, law: str):
    """Create a new log file exclusively; a clash gets a -2, -3 ... suffix, never overwrite."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    base = log_name(scenario, law)
    for k in range(1, 1000):
        name = base if k == 1 else base.replace(".mcap", f"-{k}.mcap")
        try:
            return directory / name, open(directory / name, "xb")
        except FileExistsError:
            continue
    raise FileExistsError(f"no free log name for {base} in {directory}")


class SortieRecorder:
    def __init__(
        self,
        directory: Path,
        sim: Any,
        record_every: int = 5,
        annotate_every: int = 3,
        frame_every: int = 6,
    ) -> None:
        self.sim = sim
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
        self._guard_trips = 0
        self.path, self._file = open_new_log(directory, sim.scenario.name, sim.law)
        try:
            w = Writer(self._file, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
            w.start(profile="", library=f"peregrine {gs_version}")
            self._w = w
            self._ch: dict[str, int] = {}
            schema_ids: dict[str, int] = {}
            for topic, schema in CHANNELS:
                if schema not in schema_ids:
                    schema_ids[schema] = w.register_schema(
                        schema, "jsonschema", schema_bytes(schema)
                    )
                self._ch[topic] = w.register_channel(topic, "json", schema_ids[schema])
            cam = sim.camera_model
            R = cam.R_BC
            q = _quat_xyzw(R)
            self._tf_camera = (
                '{"timestamp":{"sec":0,"nsec":0},"parent_frame_id":"body",'
                '"child_frame_id":"camera","translation":{"x":0,"y":0,"z":0},'
                f'"rotation":{{"x":{q[0]:.6f},"y":{q[1]:.6f},"z":{q[2]:.6f},"w":{q[3]:.6f}}}}}'
            )
            w.add_metadata(
                "sortie",
                {
                    "scenario": sim.scenario.name,
                    "law": sim.law,
                    "seed": str(sim.seed),
                    "camera": sim.camera.mode,
                    "gains": json.dumps(sim.loop.gains.to_dict()),
                    "software_version": f"peregrine {gs_version} (onboard {onboard_version})",
                    "scenario_source": sim.scenario.source,
                    "recorded_at_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                    "record_rate_hz": str(sim.scenario.sim.control_rate_hz / record_every),
                },
            )
            w.add_attachment(
                0, 0, "scenario.toml", "application/toml", sim.scenario.text.encode() or b""
            )
            self._calibration(0.0)
            self.event(
                0.0,
                "info",
                f"sortie start: {sim.scenario.name}, law {sim.law}, "
                f"seed {sim.seed}, camera {sim.camera.mode}",
            )
            self._file.flush()
        except OSError as exc:
            self._fail(exc)

    # ---------------------------------------------------------------- plumbing
    def _fail(self, exc: BaseException) -> None:
        self.error = f"recording stopped: {type(exc).__name__}: {exc} ({self.path})"
        self.closed = True
        with contextlib.suppress(OSError):
            self._file.close()

    def _put(self, topic: str, t_s: float, data: bytes) -> None:
        if self.closed:
            return
        try:
            ns = _ns(t_s)
            self._w.add_message(self._ch[topic], ns, data, ns)
        except OSError as exc:
            self._fail(exc)

    def _put_many(self, ns: int, items: list[tuple[int, bytes]]) -> None:
        """Several messages at one log time (channel id, data): the record tick's hot path."""
        add = self._w.add_message
        try:
            for ch, data in items:
                add(ch, ns, data, ns)
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

    def _calibration(self, t_s: float) -> None:
        cam = self.sim.camera_model
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
                "D": [0, 0, 0, 0, 0],
                "K": [f, 0, cu, 0, f, cv, 0, 0, 1],
                "R": [1, 0, 0, 0, 1, 0, 0, 0, 1],
                "P": [f, 0, cu, 0, 0, f, cv, 0, 0, 0, 1, 0],
            },
        )

    def on_tick(self, t_s: float, tel: ControlTelemetry, normal_accel_m_s2: float) -> None:
        if self.closed:
            return
        sim = self.sim
        loop = sim.loop
        if loop.gains is not self._last_gains:
            first = self._last_gains is None
            self._last_gains = loop.gains
            self._json("/gains", t_s, loop.gains.to_dict())
            if not first:
                self.event(
                    t_s,
                    "info",
                    "gains changed: "
                    + ", ".join(f"{k}={v:g}" for k, v in loop.gains.to_dict().items()),
                )
        tracking = tel.mode is LoopMode.TRACKING
        if tracking and not self._was_tracking:
            self.event(
                t_s, "info", "target acquired" if not self._was_lost else "target reacquired"
            )
        if tel.mode is LoopMode.LOST and not self._was_lost:
            self.event(t_s, "warning", "target lost: braking and holding")
        self._was_tracking, self._was_lost = tracking, tel.mode is LoopMode.LOST
        if loop.guard_trips != self._guard_trips:
            self._guard_trips = loop.guard_trips
            self.event(t_s, "error", "output guard: non-finite command replaced by hover")
        self._tick += 1
        if (self._tick - 1) % self.record_every:
            return
        ns = _ns(t_s)
        sec, nsec = divmod(ns, 1_000_000_000)
        ch = self._ch
        p, q = sim.vehicle.p, sim.vehicle.q
        qx, qy, qz, qw = q[1], q[2], q[3], q[0]
        tp = sim.target.p  # None: a live target that does not report its position
        items = [
            (ch["/world/vehicle"], (_POSE % (sec, nsec, *p, qx, qy, qz, qw)).encode()),
        ]
        half = (self._tick - 1) % (2 * self.record_every) == 0
        if half:  # the target, /tf (the vehicle pose again) and /dkf at half rate
            if tp is not None:
                items.append((ch["/world/target"], (_POSE % (sec, nsec, *tp, 0, 0, 0, 1)).encode()))
            items.append(
                (ch["/tf"], (_TF % (sec, nsec, *p, qx, qy, qz, qw, self._tf_camera)).encode())
            )
        a = tel.accel_desired_enu_m_s2
        w = tel.command.body_rates_flu_rad_s
        v = sim.vehicle.v
        if tp is not None:
            rx, ry, rz = tp[0] - p[0], tp[1] - p[1], tp[2] - p[2]
            range_js = "%.4f" % math.sqrt(rx * rx + ry * ry + rz * rz)
        else:
            range_js = "null"
        e, er = tel.e_est_px, tel.e_rate_est_px_s
        items.append(
            (
                ch["/control"],
                (
                    '{"t_s":%.6f,"mode":"%s","law":"%s","los_elev_rad":%s,"los_azim_rad":%s,'
                    '"vel_elev_rad":%s,"vel_azim_rad":%s,"accel_desired_m_s2":[%.4f,%.4f,%.4f],'
                    '"accel_normal_desired_m_s2":%s,"accel_normal_m_s2":%s,'
                    '"body_rates_cmd_rad_s":[%.5f,%.5f,%.5f],"thrust_cmd":%.5f,'
                    '"yaw_rate_cmd_rad_s":%s,"e_px":%s,"e_rate_px_s":%s,"speed_m_s":%.4f,'
                    '"range_m":%s}'
                    % (
                        t_s,
                        tel.mode.value,
                        tel.law,
                        _js(tel.los_elev_rad),
                        _js(tel.los_azim_rad),
                        _js(tel.vel_elev_rad),
                        _js(tel.vel_azim_rad),
                        a[0],
                        a[1],
                        a[2],
                        _js(tel.accel_normal_desired_m_s2),
                        _js(normal_accel_m_s2),
                        w[0],
                        w[1],
                        w[2],
                        tel.command.thrust_normalised,
                        _js(tel.yaw_rate_cmd_rad_s),
                        _js2(e),
                        _js2(er),
                        math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]),
                        range_js,
                    )
                ).encode(),
            )
        )
        if half:
            items.append((ch["/dkf"], self._dkf(t_s, tel)))
        self._put_many(ns, items)
        if (self._tick - 1) % (self.record_every * 20) == 0 and tp is not None:  # /scene
            self._scene(t_s, p, tp)

    def _dkf(self, t_s: float, tel: ControlTelemetry) -> bytes:
        loop = self.sim.loop
        state = loop.dkf.state_vector()
        if state is None:
            st = cov = "null"
        else:
            st = "[%.4f,%.4f,%.4f,%.4f]" % tuple(state[0])
            cov = "null" if state[1] is None else "[%.4f,%.4f,%.4f,%.4f]" % tuple(state[1])
        return (
            '{"t_s":%.6f,"state":%s,"cov_diag":%s,"acquired":%s,"lost":%s,'
            '"time_since_detection_s":%s}'
            % (
                t_s,
                st,
                cov,
                "true" if loop.acquired else "false",
                "true" if tel.dkf_lost else "false",
                _js(tel.dkf_time_since_detection_s),
            )
        ).encode()

    def _scene(self, t_s: float, p, tp) -> None:
        stamp = _stamp(t_s)
        d = self.sim.scenario.target.diameter_m
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
                            }
                        ],
                    }
                ],
            },
        )

    def on_frame(self, t_s: float, frame: np.ndarray | None) -> None:
        """A camera capture at ``t_s``: the frame (rendered mode) and the annotations (image
        centre, DKF estimate, latest raw detection), each at its own fraction of captures."""
        if self.closed:
            return
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
        cam = self.sim.camera_model
        ts = '{"sec":%d,"nsec":%d}' % (sec, nsec)
        clear = '{"r":0,"g":0,"b":0,"a":0}'
        circles = [
            '{"timestamp":%s,"position":{"x":%.2f,"y":%.2f},"diameter":12,"thickness":2,'
            '"fill_color":%s,"outline_color":{"r":1,"g":1,"b":1,"a":1}}'
            % (ts, cam.cu_px, cam.cv_px, clear)
        ]
        tel = self.sim.last_telemetry
        if tel is not None and tel.e_est_px is not None:
            circles.append(
                '{"timestamp":%s,"position":{"x":%.2f,"y":%.2f},"diameter":18,"thickness":2.5,'
                '"fill_color":%s,"outline_color":{"r":0.1,"g":0.76,"b":0.36,"a":1}}'
                % (ts, cam.cu_px + tel.e_est_px[0], cam.cv_px + tel.e_est_px[1], clear)
            )
        points = ""
        det = self.sim.last_detection
        if det is not None:
            u, v = det.center_px
            points = (
                '{"timestamp":%s,"type":2,"thickness":2,"points":[{"x":%.2f,"y":%.2f},'
                '{"x":%.2f,"y":%.2f},{"x":%.2f,"y":%.2f},{"x":%.2f,"y":%.2f}],'
                '"outline_color":{"r":1,"g":0.62,"b":0.11,"a":1}}'
                % (ts, u - 7, v - 7, u + 7, v - 7, u + 7, v + 7, u - 7, v + 7)
            )
        self._put(
            "/camera/annotations",
            t_s,
            ('{"circles":[%s],"points":[%s]}' % (",".join(circles), points)).encode(),
        )

    def finish(self, summary: dict[str, Any] | None, reason: str | None = None) -> None:
        """Close the file with the outcome (or the reason the sortie stopped early)."""
        if self.closed:
            return
        t_end = self.sim.time_s
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
            self._w.add_metadata(
                "outcome",
                {
                    k: json.dumps(v)
                    for k, v in (
                        summary or {"outcome": "INCOMPLETE", "reason": reason or "stopped"}
                    ).items()
                },
            )
            self._w.finish()
            self._file.close()
            self.closed = True
        except OSError as exc:
            self._fail(exc)


def _quat_xyzw(R: np.ndarray) -> tuple[float, float, float, float]:
    from onboard.geometry import rotmat_to_quat

    w, x, y, z = rotmat_to_quat(R)
    return float(x), float(y), float(z), float(w)
