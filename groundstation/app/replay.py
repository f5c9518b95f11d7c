"""Replaying a recorded sortie through the dashboard's views: the overview (poses, control,
events) is read once when the log is opened; each seek fetches the camera frame near that
time through the MCAP index, so scrubbing a long sortie does not read the whole file."""

from __future__ import annotations

import bisect
import math
from pathlib import Path
from typing import Any

from onboard.camera_model import CameraModel

from ..recording.reader import inspect_log, iter_messages, scenario_attachment
from ..scenario import ScenarioError, parse_scenario
from .scene import SceneState

OVERVIEW = ["/world/vehicle", "/world/target", "/control", "/events"]


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
            "normal_vel_m_s": None,
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

    def series(self, every: int = 1) -> dict[str, list]:
        """The recorded plot series (for overlaying this sortie on another)."""
        return {
            "t_s": self.tc[::every],
            "normal_accel_m_s2": [c.get("accel_normal_m_s2") for c in self.ctrl[::every]],
            "speed_m_s": [c.get("speed_m_s") for c in self.ctrl[::every]],
            "e_px": [c.get("e_px") for c in self.ctrl[::every]],
            "range_m": [c.get("range_m") for c in self.ctrl[::every]],
        }
