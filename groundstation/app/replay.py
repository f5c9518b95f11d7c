"""Replaying a recorded sortie through the dashboard's views: the overview (poses, control,
events) is read once when the log is opened; each seek fetches the camera frame near that
time through the MCAP index, so scrubbing a long sortie does not read the whole file."""

from __future__ import annotations

import bisect
import json
import math
from pathlib import Path
from typing import Any

from onboard.camera_model import CameraModel

from ..recording.reader import inspect_log, iter_messages, scenario_attachment
from ..scenario import ScenarioError, parse_scenario
from .scene import SceneState

OVERVIEW = ["/world/vehicle", "/world/target", "/control", "/events", "/gains"]
PLOT_KEYS = ("normal_accel_m_s2", "speed_m_s", "normal_vel_m_s", "e_x_px", "e_y_px", "range_m")


def _unit(az: float, el: float) -> tuple[float, float, float]:
    return (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))


def normal_vel_m_s(c: dict) -> float | None:
    """The velocity's component normal to the line of sight (m/s), from a recorded /control
    message: speed and the velocity and LOS angles (elevation, azimuth) give it as
    |v| sin(angle between v and LOS)."""
    try:
        speed = float(c["speed_m_s"])
        los = _unit(float(c["los_azim_rad"]), float(c["los_elev_rad"]))
        vel = _unit(float(c["vel_azim_rad"]), float(c["vel_elev_rad"]))
    except (KeyError, TypeError, ValueError):
        return None
    cos_a = max(-1.0, min(1.0, sum(a * b for a, b in zip(los, vel, strict=True))))
    return speed * math.sqrt(1.0 - cos_a * cos_a)


def _p(msg: dict) -> tuple[float, float, float]:
    pos = msg["pose"]["position"]
    return pos["x"], pos["y"], pos["z"]


class ReplayPlayer:
    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.info = inspect_log(self.path)
        self.tv: list[float] = []
        self.vp: list[tuple[float, float, float]] = []
        self.vq: list[tuple[float, float, float, float]] = []
        self.tt: list[float] = []
        self.tp: list[tuple[float, float, float]] = []
        self.tc: list[float] = []
        self.ctrl: list[dict] = []
        self.events: list[tuple[float, str]] = []
        self.gain_changes: list[tuple[float, dict]] = []
        for topic, t, m in iter_messages(self.path, OVERVIEW):
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
            elif topic == "/gains":
                self.gain_changes.append((t, m))
            else:
                self.events.append((t, m.get("message", "")))
        if not self.tv or not self.tt:
            raise ValueError(f"{self.path.name}: no vehicle or target track recorded")
        self.duration_s = max(self.tv[-1], self.tt[-1])
        self.camera = CameraModel()
        self.diameter_m = 0.3
        text = scenario_attachment(self.path)
        if text:
            try:
                sc = parse_scenario(text, source=self.path.name)
                c = sc.camera
                self.camera = CameraModel(
                    c.width_px, c.height_px, c.hfov_deg, c.mount_pitch_deg, c.mount_roll_deg
                )
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
        for (_, a), (t, b) in zip(self.gain_changes, self.gain_changes[1:], strict=False):
            for k, v in b.items():
                if k in a and a[k] != v:
                    out.append([round(t, 3), "gain", f"{k} {a[k]:g} → {v:g}"])
        miss = self.info.miss_m
        out.append(
            [
                round(self.closest_time_s, 3),
                "closest",
                "closest approach" + ("" if miss is None else f": miss {miss:.3f} m"),
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
            "file": self.path.name,
            "scenario": self.info.scenario,
            "law": self.info.law,
            "seed": self.info.seed,
            "gains": gains,
        }

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
            f"{self.info.outcome} miss {self.info.miss_m:.3f} m"
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
        last = None
        for _topic, _t, m in iter_messages(
            self.path, ["/camera/image"], max(t - 0.5, 0.0), t + 1e-6
        ):
            last = m
        return None if last is None else last.get("data")

    def snapshot(self, t: float) -> dict[str, Any]:
        st = self.scene_state(t)
        c = self.ctrl[self._at(self.tc, t)] if self.ctrl else {}
        vp, tp = st.vehicle_p, st.target_p
        rng = math.dist(vp, tp)
        cam = self.camera
        return {
            "t": round(t, 4),
            "vehicle": {"p": list(vp), "q": list(st.vehicle_q)},
            "target": {"p": list(tp), "diameter_m": self.diameter_m},
            "range_m": rng,
            "speed_m_s": c.get("speed_m_s"),
            "normal_vel_m_s": normal_vel_m_s(c) if c else None,
            "normal_accel_m_s2": c.get("accel_normal_m_s2"),
            "image": {
                "w": cam.width_px,
                "h": cam.height_px,
                "f": cam.f_px,
                "vfov_deg": cam.vfov_deg,
            },
            "e_est_px": c.get("e_px"),
            "e_raw_px": None,
            "mode": c.get("mode"),
        }

    def series(self, every: int = 1) -> dict[str, Any]:
        """The whole recorded sortie for the plots: ``t_s``, the dashboard's plot columns and
        every other numeric /control field (arrays split as ``name.0``, ``name.1``), and the
        timeline's markers."""
        rows = self.ctrl[::every]
        cols: dict[str, list] = {k: [] for k in PLOT_KEYS}
        extra: dict[str, list] = {}
        for i, c in enumerate(rows):
            e = c.get("e_px")
            cols["normal_accel_m_s2"].append(c.get("accel_normal_m_s2"))
            cols["speed_m_s"].append(c.get("speed_m_s"))
            cols["normal_vel_m_s"].append(normal_vel_m_s(c))
            cols["e_x_px"].append(e[0] if e else None)
            cols["e_y_px"].append(e[1] if e else None)
            cols["range_m"].append(c.get("range_m"))
            for k, v in c.items():
                items = list(enumerate(v)) if isinstance(v, list) else [(None, v)]
                for j, x in items:
                    if isinstance(x, bool) or not isinstance(x, (int, float, type(None))):
                        continue
                    name = k if j is None else f"{k}.{j}"
                    if name == "t_s":
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
            "events": self.timeline,
            "sortie": self.describe(),
        }
