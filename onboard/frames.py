"""One typed frame of a sortie at a control tick, and the observers that consume frames.

Four producers emit frames: the simulator (:class:`~groundstation.sim.simulation.Simulation`,
from its truth and its onboard loop), live mode (:mod:`groundstation.app.live_frames`, from
the onboard component's MAVLink telemetry), replay (:class:`~groundstation.app.replay.
ReplayPlayer`, from a recorded MCAP) and the onboard runtime itself
(:mod:`onboard.runtime.foxglove`, from its loop). The consumers read nothing else: the
recorder (:class:`~groundstation.recording.writer.SortieRecorder`) and Foxglove live (both
:class:`~onboard.channels.builder.ChannelBuilder` s), the dashboard's snapshot builder
(:func:`groundstation.app.snapshot.frame_snapshot`), campaign traces and the bench.

An observer is told, in order: ``start`` once (what the sortie is), ``frame`` at control ticks
and ``image`` at camera captures (interleaved, in time order), then ``finish`` once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from onboard.camera_model import CameraModel
from onboard.datatypes import ControlTelemetry, Detection
from onboard.gains import Gains

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class SortieStart:
    """What a sortie is, told to observers before its first frame."""

    scenario: str  # name ("live" for a live flight)
    law: str  # a GuidanceLaw value
    seed: int
    camera: str  # camera mode ("projected", "rendered", "live")
    camera_model: CameraModel
    target_diameter_m: float
    control_rate_hz: float
    gains: Gains  # in force at the start
    scenario_source: str  # where the scenario came from (a path, "live MAVLink")
    scenario_toml: str  # the scenario as flown ("" when there is none)
    t0_s: float = 0.0  # the producer's clock at the start: recordings count from here
    estimate_profile: str = ""  # the simulator's state-estimate profile ("ideal": ideal sensors)


@dataclass(frozen=True, slots=True)
class SortieEvent:
    time_s: float  # producer's clock
    level: str  # debug | info | warning | error | fatal
    message: str


@dataclass(slots=True)  # not frozen: a frozen init costs the simulator's tick 3 us more
class Frame:
    """The sortie at one control tick, on the producer's clock (simulated time in the
    simulator, the onboard clock live, the recording's clock in replay). World frame ENU.
    Read-only by convention: observers share one frame (``dataclasses.replace`` to vary it)."""

    time_s: float
    vehicle_p_enu_m: Vec3
    vehicle_q_wxyz: tuple[float, float, float, float]  # body FLU -> world ENU
    vehicle_v_enu_m_s: Vec3 | None  # None: a recording without velocity
    target_p_enu_m: Vec3 | None  # None: a live target that does not report its position
    telemetry: ControlTelemetry | None  # what the loop computed (None before its first tick)
    normal_accel_m_s2: float | None  # actual, normal to the velocity
    detection: Detection | None  # latest detection delivered to the loop
    dkf_state_px: tuple[float, float, float, float] | None  # (e_u, e_v, rate_u, rate_v)
    dkf_cov_diag: tuple[float, float, float, float] | None
    acquired: bool  # the loop has had a target estimate at some point
    gains: Gains  # in force at this tick
    guard_trips: int  # output-guard trips so far
    events: tuple[SortieEvent, ...] = ()  # producer events since the previous frame

    @property
    def range_m(self) -> float | None:
        tp, p = self.target_p_enu_m, self.vehicle_p_enu_m
        if tp is None:
            return None
        return math.sqrt((tp[0] - p[0]) ** 2 + (tp[1] - p[1]) ** 2 + (tp[2] - p[2]) ** 2)

    @property
    def speed_m_s(self) -> float | None:
        v = self.vehicle_v_enu_m_s
        return None if v is None else math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


class SortieObserver(Protocol):
    """Consumes a sortie as it is produced (see the module docstring for the order)."""

    def start(self, info: SortieStart) -> None: ...

    def frame(self, frame: Frame) -> None: ...

    def image(self, time_s: float, image: np.ndarray | None) -> None: ...

    def finish(self, time_s: float, summary: dict[str, Any] | None, reason: str | None) -> None:
        """``summary``: the outcome (``SortieResult.to_json_dict()`` or live's); None with a
        ``reason`` when the sortie stopped before its outcome."""
        ...


class FrameList:
    """An observer that keeps every frame (campaign traces, tests)."""

    def __init__(self) -> None:
        self.info: SortieStart | None = None
        self.frames: list[Frame] = []
        self.summary: dict[str, Any] | None = None

    def start(self, info: SortieStart) -> None:
        self.info = info

    def frame(self, frame: Frame) -> None:
        self.frames.append(frame)

    def image(self, time_s: float, image: np.ndarray | None) -> None:
        pass

    def finish(self, time_s: float, summary: dict[str, Any] | None, reason: str | None) -> None:
        self.summary = summary
