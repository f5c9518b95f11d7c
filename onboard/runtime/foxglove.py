"""``onboard run --foxglove``: the recording's channels live over Foxglove's WebSocket protocol
from the vehicle itself, so an engineer opens Foxglove on a running sortie without the ground
station. The channels and messages are the recording's (:mod:`onboard.channels`: one
definition), built from :class:`~onboard.frames.Frame` s of the loop's own state.

The control thread never waits on it: every ``TELEMETRY_EVERY``-th tick it appends the
references of what it already holds (the flight controller's pose, the loop's telemetry, the
latest detection, the DKF estimate) to a bounded deque, O(1) and lock-free; a full deque drops
its oldest sample (``dropped`` counts them). :class:`FoxglovePublisher`, a thread at a lower
scheduling priority (nice +10, as the video's), builds the frames, encodes the messages
(camera JPEGs included, at 5 Hz) and hands them to foxglove-sdk's server, which queues per
client and drops for a slow one. Only channels a client subscribes to are encoded; the
calibration and the gains, sent once per sortie, are sent again when a client subscribes
(:meth:`~onboard.channels.builder.ChannelBuilder.republish`).
Events (STATUSTEXT) go through their own bounded deque and ride on the next frame built.

A "sortie" here is the life of one loop: it starts when the loop is built (the first camera
frame, or a rebuild after a camera, airframe or law parameter changed) and finishes when the
runtime stops or the loop is rebuilt. Timestamps are on the onboard clock from that start.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from ..camera_model import CameraModel
from ..control.guidance import normal_component
from ..datatypes import LoopMode
from ..frames import Frame, SortieEvent, SortieStart
from ..gains import Gains

if TYPE_CHECKING:
    from ..channels.live import FoxgloveLive

QUEUE = 64  # samples (about 1.3 s at 50 Hz) before the oldest is dropped
PUBLISH_NICE = 10  # below the control thread (Linux)
IMAGE_EVERY_S = 0.1  # annotations at 10 Hz; every second one with its JPEG (5 Hz)
TARGET_DIAMETER_M = 0.3  # drawn size only (/scene needs the target's position: none onboard)
_LEVELS = {"critical": "fatal", "error": "error", "warning": "warning", "info": "info"}


class FoxglovePublisher(threading.Thread):
    """Publishes what the control thread offers (see the module docstring). ``latest_image``
    returns the camera thread's newest ``(capture time s, BGR image)`` or None."""

    def __init__(self, live: FoxgloveLive, latest_image=None, on_error=None) -> None:
        super().__init__(name="foxglove", daemon=True)
        self.live = live
        self.latest_image = latest_image
        self.on_error = on_error
        self._samples: deque = deque(maxlen=QUEUE)
        self._events: deque = deque(maxlen=QUEUE)
        self._start: SortieStart | None = None  # a loop was built: a new sortie
        self._halt = threading.Event()
        self.offered = 0
        self.dropped = 0
        self.published_frames = 0
        self.cpu_s = 0.0  # this thread's CPU time
        self.error: str | None = None

    # ------------------------------------------------------------------ the control thread
    def new_sortie(
        self, t0_s: float, law: str, camera: CameraModel, gains: Gains, control_rate_hz: float
    ) -> None:
        """The loop was (re)built at ``t0_s`` (onboard clock, s)."""
        self._start = SortieStart(
            scenario="onboard",
            law=law,
            seed=0,
            camera="live",
            camera_model=camera,
            target_diameter_m=TARGET_DIAMETER_M,
            control_rate_hz=control_rate_hz,
            gains=gains,
            scenario_source="onboard run",
            scenario_toml="",
            t0_s=t0_s,
        )

    def offer(self, t_s, pos_enu_m, vel_enu_m_s, q_wxyz, tel, detection, dkf, gains, trips):
        """One control tick's state (references; nothing is copied or computed here)."""
        self.offered += 1
        if len(self._samples) == QUEUE:
            self.dropped += 1
        self._samples.append(
            (t_s, pos_enu_m, vel_enu_m_s, q_wxyz, tel, detection, dkf, gains, trips)
        )

    def event(self, t_s: float, severity: str, text: str) -> None:
        self._events.append(SortieEvent(t_s, _LEVELS.get(severity, "info"), text))

    def stop(self) -> None:
        self._halt.set()

    # ------------------------------------------------------------------ this thread
    def run(self) -> None:
        with contextlib.suppress(AttributeError, OSError):  # Linux: this thread only
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), PUBLISH_NICE)
        builder = None
        acquired = False
        prev_v: tuple[float, np.ndarray] | None = None
        next_image_s = 0.0
        last_t = None
        try:
            while not self._halt.wait(0.01):
                start, self._start = self._start, None
                if start is not None:
                    if builder is not None:
                        builder.finish(last_t or start.t0_s, None, "loop rebuilt")
                    builder = self.live.observer(record_every=1, annotate_every=1, frame_every=2)
                    builder.start(start)
                    acquired, prev_v = False, None
                if builder is None:
                    self._samples.clear()
                    continue
                while self._samples:
                    t_s, p, v, q, tel, det, dkf, gains, trips = self._samples.popleft()
                    if p is None or q is None or tel is None:
                        continue  # no frame to build yet (its events wait for one)
                    events = []
                    while self._events:
                        events.append(self._events.popleft())
                    a_n = None
                    if v is not None:
                        if prev_v is not None and t_s > prev_v[0]:
                            a_n = normal_component((v - prev_v[1]) / (t_s - prev_v[0]), v)
                        prev_v = (t_s, v)
                    acquired = acquired or (tel is not None and tel.mode is LoopMode.TRACKING)
                    builder.frame(
                        Frame(
                            time_s=t_s,
                            vehicle_p_enu_m=tuple(map(float, p)),
                            vehicle_q_wxyz=tuple(map(float, q)),
                            vehicle_v_enu_m_s=None if v is None else tuple(map(float, v)),
                            target_p_enu_m=None,
                            telemetry=tel,
                            normal_accel_m_s2=a_n,
                            detection=det,
                            dkf_state_px=None if dkf is None else tuple(map(float, dkf[0])),
                            dkf_cov_diag=None if dkf is None else tuple(map(float, dkf[1])),
                            acquired=acquired,
                            gains=gains,
                            guard_trips=trips,
                            events=tuple(events),
                        )
                    )
                    last_t = t_s
                    self.published_frames += 1
                if self.latest_image is not None and last_t is not None and last_t >= next_image_s:
                    got = self.latest_image()
                    if got is not None:
                        next_image_s = last_t + IMAGE_EVERY_S
                        t_img, image = got
                        # no JPEG encoded for nobody
                        builder.image(
                            t_img, image if self.live.subscribed("/camera/image") else None
                        )
                self.cpu_s = time.thread_time()
            if builder is not None:
                builder.finish(last_t or 0.0, None, "onboard stopped")
        except Exception as exc:  # publishing ends, never the flight
            self.error = f"foxglove stopped: {type(exc).__name__}: {exc}"
            if self.on_error is not None:
                self.on_error(self.error)

    def stats(self) -> dict:
        return {
            "offered": self.offered,
            "dropped": self.dropped,
            "published_frames": self.published_frames,
            "cpu_s": self.cpu_s,
            "error": self.error,
        }
