"""Replaying a recorded sortie through the dashboard's views: the overview (poses, control,
DKF, gains, events) is read once when the log is opened; :meth:`ReplayPlayer.frame` rebuilds
the sortie's :class:`~onboard.frames.Frame` at any time from it (the same frame the
simulator or live mode produced, to the recording's precision); each seek fetches the camera
frame near that time through the MCAP index, so scrubbing a long sortie does not read the
whole file."""

from __future__ import annotations

import bisect
import functools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from onboard import messages
from onboard.camera_model import CameraModel
from onboard.datatypes import ControlTelemetry, Detection, LoopMode, RateThrustCommand
from onboard.frames import Frame
from onboard.gains import GainError, Gains

from ..recording.reader import SCENARIO_ATTACHMENT, iter_messages, read_log
from ..scenario import ScenarioError, parse_scenario
from .numbers import fmt_num
from .scene import SceneState
from .snapshot import frame_snapshot

OVERVIEW = ["/world/vehicle", "/world/target", "/control", "/dkf", "/gains", "/events"]
CAMERA_TOPIC = "/camera/image"
FRAME_WINDOW_S = 0.5  # a camera frame older than this at the cursor is not shown
PLOT_KEYS = ("normal_accel_m_s2", "speed_m_s", "normal_vel_m_s", "e_x_px", "e_y_px", "range_m")


def _p(msg: dict) -> tuple[float, float, float]:
    pos = msg["pose"]["position"]
    return pos["x"], pos["y"], pos["z"]


class ReplayPlayer:
    def __init__(self, path: Path, name: str | None = None) -> None:
        self.path = Path(path)
        self.name = name or self.path.name  # as the API names it (relative to the log folder)
        # one pass over the file: its status and summary, the overview and the scenario
        log = read_log(self.path, OVERVIEW, (CAMERA_TOPIC,))
        self.info = log.info
        self.frame_times = log.times[CAMERA_TOPIC]  # of the recorded camera frames (s)
        self.tv: list[float] = []
        self.vp: list[tuple[float, float, float]] = []
        self.vq: list[tuple[float, float, float, float]] = []
        self.tt: list[float] = []
        self.tp: list[tuple[float, float, float]] = []
        self.tc: list[float] = []
        self.ctrl: list[dict] = []
        self.events: list[tuple[float, str]] = []
        self.td: list[float] = []
        self.dkf: list[dict] = []
        self.tg: list[float] = []
        self.gains: list[Gains] = []
        for topic, t, m in log.messages:
            if topic == "/world/vehicle":
                o = m["pose"]["orientation"]
                self.tv.append(t)
                self.vp.append(_p(m))
                self.vq.append((o["w"], o["x"], o["y"], o["z"]))
            elif topic == "/world/target":
                self.tt.append(t)
                self.tp.append(_p(m))
            elif topic == "/control":
                self.tc.append(t)
                self.ctrl.append(m)
            elif topic == "/dkf":
                self.td.append(t)
                self.dkf.append(m)
            elif topic == "/gains":
                try:
                    g = Gains().replace(**{k: float(v) for k, v in m.items()})
                except (GainError, TypeError, ValueError):
                    continue  # gains this version does not know: the page shows defaults
                self.tg.append(t)
                self.gains.append(g)
            else:
                self.events.append((t, m.get("message", "")))
        if not self.tv or not self.tt:
            raise ValueError(f"{self.path.name}: no vehicle or target track recorded")
        self.duration_s = max(self.tv[-1], self.tt[-1])
        self.camera = CameraModel()
        self.diameter_m = 0.3
        text = self.scenario_text = log.attachment_text(SCENARIO_ATTACHMENT)
        if text:
            from ..sim.beliefs import true_camera  # the simulator: imported at the first replay

            try:
                sc = parse_scenario(text, source=self.path.name)
                self.camera = true_camera(sc)  # the camera the sortie's frames came from
                self.diameter_m = sc.target.diameter_m
            except ScenarioError:
                pass
        # closest approach: from the recorded outcome, else the nearest recorded pass
        meta = self.info.metadata.get("outcome", {})
        t_ca = None
        if "intercept_time_s" in meta:
            try:
                t_ca = float(meta["intercept_time_s"])
            except ValueError:
                t_ca = None
        if t_ca is None:
            ranges = [c.get("range_m") or math.inf for c in self.ctrl]
            t_ca = self.tc[ranges.index(min(ranges))] if ranges else self.duration_s
        self.closest_time_s = min(max(t_ca, 0.0), self.duration_s)
        self.timeline = self._timeline()

    def _timeline(self) -> list[list]:
        """Markers for the plots' shared timeline: [t_s, kind, text], by time."""
        out: list[list] = []
        for t, text in self.events:
            if text.startswith("gains changed"):
                continue  # shown below as old -> new
            low = text.lower()
            kind = "detection" if ("lost" in low or "acquired" in low) else "event"
            out.append([round(t, 3), kind, text])
        for a, b, t in zip(self.gains, self.gains[1:], self.tg[1:], strict=False):
            old, new = a.to_dict(), b.to_dict()
            for k, v in new.items():
                if old[k] != v:
                    out.append([round(t, 3), "gain", f"{k} {fmt_num(old[k])} → {fmt_num(v)}"])
        miss = self.info.miss_m
        out.append(
            [
                round(self.closest_time_s, 3),
                "closest",
                "closest approach" + ("" if miss is None else f": miss {fmt_num(miss)} m"),
            ]
        )
        return sorted(out, key=lambda e: e[0])

    def describe(self) -> dict[str, Any]:
        """Who this sortie is, for a legend: file, scenario, law, seed and gains flown."""
        meta = self.info.metadata.get("sortie", {})
        try:
            gains = json.loads(meta.get("gains", "{}"))
        except ValueError:
            gains = {}
        return {
            "file": self.name,
            "scenario": self.info.scenario,
            "law": self.info.law,
            "seed": self.info.seed,
            "gains": gains,
        }

    def gains_not_default(self) -> dict[str, float]:
        """The gains the sortie started with that differ from the defaults."""
        flown, default = self.describe()["gains"], Gains().to_dict()
        return {k: v for k, v in flown.items() if k in default and v != default[k]}

    @staticmethod
    def _at(times: list[float], t: float) -> int:
        return max(bisect.bisect_right(times, t + 1e-9) - 1, 0)

    def scene_state(self, t: float) -> SceneState:
        i, j = self._at(self.tv, t), self._at(self.tt, t)
        done = t >= self.duration_s - 1e-6 and self.info.outcome is not None
        closest = None
        if done:
            k = self._at(self.tv, self.closest_time_s)
            closest = self.vp[k]
        label = (
            f"{self.info.outcome} miss {fmt_num(self.info.miss_m)} m"
            if done and self.info.miss_m is not None
            else ""
        )
        return SceneState(t, self.vp[i], self.vq[i], self.tp[j], closest, label)

    def trails(self, t: float, every: int = 2) -> tuple[list, list]:
        i, j = self._at(self.tv, t), self._at(self.tt, t)
        return (
            [list(p) for p in self.vp[: i + 1 : every]],
            [list(p) for p in self.tp[: j + 1 : every]],
        )

    def frame_b64(self, t: float) -> str | None:
        """The last camera frame at or before t, found through the index."""
        return self.frame_at(t)[1]

    def frame_time_at(self, t: float) -> float | None:
        """The log time of the camera frame :meth:`frame_at` finds at ``t`` (None: none), from
        the times read with the overview: no read of the file."""
        k = bisect.bisect_right(self.frame_times, t + 1e-6) - 1
        if k < 0 or self.frame_times[k] < t - FRAME_WINDOW_S:
            return None
        return round(self.frame_times[k], 6)

    def frame_at(self, t: float) -> tuple[float | None, str | None]:
        """(its log time, the JPEG as base64) of the last camera frame at or before ``t``
        and at most FRAME_WINDOW_S before it, found through the index; (None, None) if none."""
        last, last_t = None, None
        for _topic, tf, m in iter_messages(
            self.path, [CAMERA_TOPIC], max(t - FRAME_WINDOW_S, 0.0), t + 1e-6
        ):
            if tf <= t + 1e-6:
                last, last_t = m, tf
        if last is None or not last.get("data"):
            return None, None
        return round(last_t, 6), last.get("data")

    def _velocity(self, i: int, c: dict) -> tuple[float, float, float] | None:
        """The recorded velocity; a recording made before it was recorded: the poses'
        finite difference."""
        v = c.get("vel_m_s")
        if v is not None:
            return (v[0], v[1], v[2])
        if len(self.tv) < 2:
            return None
        a, b = (i - 1, i) if i > 0 else (0, 1)
        dt = self.tv[b] - self.tv[a]
        if dt <= 0:
            return None
        pa, pb = self.vp[a], self.vp[b]
        return tuple((pb[k] - pa[k]) / dt for k in range(3))

    def frame(self, t: float) -> Frame:
        """The sortie at time ``t``: the last recorded vehicle pose, target pose, control, DKF
        state and gains at or before ``t`` (the recording's clock)."""
        i, j = self._at(self.tv, t), self._at(self.tt, t)
        c = self.ctrl[self._at(self.tc, t)] if self.ctrl else None
        d = self.dkf[self._at(self.td, t)] if self.dkf else {}
        gains = self.gains[self._at(self.tg, t)] if self.gains else Gains()
        tel = det = None
        if c is not None:
            tel = _telemetry(c, d)
            raw, raw_t = c.get("e_raw_px"), c.get("raw_capture_t_s")
            if raw is not None and raw_t is not None:
                u, v = self.camera.cu_px + raw[0], self.camera.cv_px + raw[1]
                det = Detection(raw_t, (u, v), (u - 5, v - 5, 10, 10), 100.0)
        state, cov = d.get("state"), d.get("cov_diag")
        return Frame(
            time_s=t,
            vehicle_p_enu_m=self.vp[i],
            vehicle_q_wxyz=self.vq[i],
            vehicle_v_enu_m_s=self._velocity(i, c or {}),
            target_p_enu_m=self.tp[j],
            telemetry=tel,
            normal_accel_m_s2=None if c is None else c.get("accel_normal_m_s2"),
            detection=det,
            dkf_state_px=None if state is None else tuple(state),
            dkf_cov_diag=None if cov is None else tuple(cov),
            acquired=bool(d.get("acquired", tel is not None and tel.mode is LoopMode.TRACKING)),
            gains=gains,
            guard_trips=0,
        )

    def series(self, every: int = 1, fields: bool = True) -> dict[str, Any]:
        """The whole recorded sortie for the plots: ``t_s``, the dashboard's plot columns and
        (``fields``) every other numeric /control and /dkf field (``dkf.`` names; arrays split
        as ``name.0``, ``name.1``; /dkf as last recorded at each /control time), and the
        timeline's markers."""
        # through the one snapshot builder: the plots show what the page shows live
        rows = self.ctrl[::every]
        cols: dict[str, list] = {k: [] for k in PLOT_KEYS}
        extra: dict[str, list] = {}
        for i, (t, c) in enumerate(zip(self.tc[::every], rows, strict=True)):
            snap = frame_snapshot(self.frame(t), self.camera, self.diameter_m)
            e = snap["e_est_px"]
            for k in ("normal_accel_m_s2", "speed_m_s", "normal_vel_m_s", "range_m"):
                cols[k].append(snap[k])
            cols["e_x_px"].append(e[0] if e else None)
            cols["e_y_px"].append(e[1] if e else None)
            if not fields:
                continue
            d = self.dkf[self._at(self.td, t)] if self.dkf else {}
            for prefix, msg in (("", c), ("dkf.", d)):  # /dkf as last recorded at t
                for k, v in msg.items():
                    items = list(enumerate(v)) if isinstance(v, list) else [(None, v)]
                    for j, x in items:
                        if isinstance(x, bool) or not isinstance(x, (int, float, type(None))):
                            continue
                        name = prefix + (k if j is None else f"{k}.{j}")
                        if k == "t_s":
                            continue
                        col = extra.setdefault(name, [None] * i)
                        col.append(x)
            for col in extra.values():
                if len(col) < i + 1:
                    col.append(None)
        for name in [k for k in extra if f"{k}.0" in extra]:
            del extra[name]  # an array recorded as None at first: its elements are kept
        return {
            "t_s": self.tc[::every],
            "columns": cols,
            "fields": extra,
            # from the one message definition: the page labels the plots it adds with these
            "units": {
                k: u
                for k, u in (
                    *messages.units(messages.CONTROL).items(),
                    *((f"dkf.{k}", u) for k, u in messages.units(messages.DKF).items()),
                )
                if k in extra
            },
            "events": self.timeline,
            "sortie": self.describe(),
        }


OVERLAY_MAX = 20  # sorties overlaid at once


def overlay_entry(path: Path, name: str) -> dict[str, Any]:
    """One recorded sortie as the overlay shows it: who it is, its outcome, the plot columns
    and the vehicle's position relative to the target (m, east-north-up) at the same times.
    Kept per file (path, size, modification time): scrubbing or re-opening costs nothing."""
    st = Path(path).stat()
    return _overlay_entry(str(path), name, st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _overlay_entry(path: str, name: str, _size: int, _mtime_ns: int) -> dict[str, Any]:
    p = ReplayPlayer(Path(path), name)
    s = p.series(fields=False)
    rel = []
    for t in s["t_s"]:
        v, g = p.vp[p._at(p.tv, t)], p.tp[p._at(p.tt, t)]
        rel.append([round(v[k] - g[k], 3) for k in range(3)])
    return {
        **p.describe(),
        "outcome": p.info.outcome,
        "miss_m": p.info.miss_m,
        "intercept_time_s": p.closest_time_s,
        "duration_s": p.duration_s,
        "t_s": s["t_s"],
        "columns": s["columns"],
        "rel_m": rel,
    }


def _num(x: float | None, missing: float = math.nan) -> float:
    return missing if x is None else float(x)


def _telemetry(c: dict, d: dict) -> ControlTelemetry | None:
    """A recorded /control message (and the /dkf one before it) as the loop's telemetry."""
    try:
        mode = LoopMode(c.get("mode"))
    except ValueError:
        return None
    e, e_rate = c.get("e_px"), c.get("e_rate_px_s")
    w = c.get("body_rates_cmd_rad_s") or (0.0, 0.0, 0.0)
    t_s = _num(c.get("t_s"))
    return ControlTelemetry(
        time_s=t_s,
        mode=mode,
        law=c.get("law", ""),
        e_est_px=None if e is None else (e[0], e[1]),
        e_rate_est_px_s=None if e_rate is None else (e_rate[0], e_rate[1]),
        los_elev_rad=_num(c.get("los_elev_rad")),
        los_azim_rad=_num(c.get("los_azim_rad")),
        vel_elev_rad=_num(c.get("vel_elev_rad")),
        vel_azim_rad=_num(c.get("vel_azim_rad")),
        accel_desired_enu_m_s2=np.array(c.get("accel_desired_m_s2") or (0.0, 0.0, 0.0)),
        accel_normal_desired_m_s2=_num(c.get("accel_normal_desired_m_s2")),
        yaw_rate_cmd_rad_s=_num(c.get("yaw_rate_cmd_rad_s")),
        command=RateThrustCommand(t_s, np.array(w), _num(c.get("thrust_cmd"))),
        dkf_time_since_detection_s=_num(d.get("time_since_detection_s"), math.inf),
        dkf_lost=bool(d.get("lost", False)),
        guard_tripped=False,
    )
