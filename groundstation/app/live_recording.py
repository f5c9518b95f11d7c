"""A live sortie's recording: from the accepted start until the onboard component reports the
sortie finished (or the link stays lost). It is told the frames live mode builds and the events
heard, hands them to the recorder, and keeps the closest approach."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

from onboard.frames import Frame, SortieEvent, SortieStart

from ..recording.writer import SortieRecorder
from ..sim.outcome import closest_in_step

# The ground link silent this long ends a recording. A shorter gap (a loaded ground computer,
# a radio fade) is an event in it, and the sortie goes on being recorded when the link is back.
LINK_GIVE_UP_S = 30.0


class LiveRecording:
    def __init__(self, log_dir: Path, start: SortieStart, foxglove=None) -> None:
        """``foxglove``: a :class:`~onboard.channels.live.FoxgloveLive` that publishes
        the same channels as the file, or None."""
        self.law = start.law
        self.t0_s = self.last_s = start.t0_s  # onboard clock: start, last recorded frame
        self.acquired = False
        self.miss_m: float | None = None
        self._events: list[SortieEvent] = []  # heard since the last recorded frame
        self._last_frame: Frame | None = None
        self._rel_prev: list[float] | None = None
        self._link_down_since: float | None = None  # the ground's monotonic clock, s
        # every tick (50 Hz) and annotation; no camera frames reach the ground
        self.recorder = SortieRecorder(
            Path(log_dir), record_every=1, annotate_every=1, frame_every=1000000
        )
        self.observers = [self.recorder]
        if foxglove is not None:
            self.observers.append(
                foxglove.observer(record_every=1, annotate_every=1, frame_every=1000000)
            )
        for o in self.observers:
            o.start(start)

    @property
    def elapsed_s(self) -> float:
        return max(self.last_s - self.t0_s, 0.0)

    def status(self) -> dict[str, Any]:
        rec = self.recorder
        return {"file": rec.path.name, "error": rec.error, "closed": rec.closed}

    def event(self, level: str, message: str) -> None:
        """Recorded with the next frame, at the time of the last one."""
        self._events.append(SortieEvent(self.last_s, level, message))

    def link_given_up(self, up: bool, now_s: float) -> bool:
        """Note the ground link's state at ``now_s`` (the ground's monotonic clock, s): a loss
        and a return are events; True once it has been down for ``LINK_GIVE_UP_S``."""
        down = self._link_down_since
        if up:
            if down is not None:
                self.event("info", f"telemetry link back after {now_s - down:.1f} s")
                self._link_down_since = None
            return False
        if down is None:
            self._link_down_since = down = now_s
            self.event("warning", "telemetry link lost: recording goes on when it is back")
        return now_s - down >= LINK_GIVE_UP_S

    def record(self, frame: Frame) -> None:
        frame = dataclasses.replace(frame, events=tuple(self._events))
        self._events = []
        self.acquired = frame.acquired
        self.last_s = frame.time_s
        self._last_frame = frame
        for o in self.observers:
            o.frame(frame)
            if int(frame.time_s * 50) % 5 == 0:  # annotations at about 10 Hz
                o.image(frame.time_s, None)

    def track_miss(self, rel: list[float] | None) -> None:
        """Closest approach: ``rel`` (target minus vehicle at this control tick, m; None when
        either is unknown), the relative motion linear between ticks (the simulator's
        continuous-time test)."""
        if rel is None:
            self._rel_prev = None
            return
        if self._rel_prev is None:
            dist = math.sqrt(sum(c * c for c in rel))
        else:
            dist = closest_in_step(self._rel_prev, rel)[0]
        self._rel_prev = rel
        self.miss_m = dist if self.miss_m is None else min(self.miss_m, dist)

    def finish(self, outcome: str, reason: str) -> None:
        """Close the file: events heard after the last frame, then the outcome."""
        if self._events and self._last_frame is not None:
            late = dataclasses.replace(self._last_frame, events=tuple(self._events))
            for o in self.observers:
                o.frame(late)
            self._events = []
        summary = {
            "outcome": outcome,
            "miss_m": self.miss_m,
            "intercept_time_s": self.elapsed_s,
            "reason": reason,
            "law": self.law,
        }
        for o in self.observers:
            o.finish(self.last_s, summary)
