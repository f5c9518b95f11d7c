"""The simulated strapdown camera and detection pipeline.

Frames are captured at the camera rate. ``projected`` mode projects the target analytically
(pinhole) and adds pixel noise; ``rendered`` mode draws a real frame and runs the onboard
detector on it. Both apply the same capture-to-result delay with jitter and random dropouts,
and deliver each detection stamped with its capture time when its delay has passed.

:class:`DetectorFaults` adds what a real detector does (all off by default, each switched on
by a ``[camera]`` key): a minimum blob size (a range limit: the projected camera would
otherwise report a 0.06 px balloon), false red blobs (clutter) and bursty frame drops (a
Gilbert-Elliott two-state channel).
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from onboard.camera_model import CameraModel
from onboard.datatypes import Detection
from onboard.perception import RedBalloonDetector

from ..scenario import CAMERA_MODES, CameraSpec
from .render import FrameRenderer


def apparent_radius_px(model: CameraModel, p_cam: np.ndarray, diameter_m: float) -> float:
    """Image radius (px) of a sphere of ``diameter_m`` at ``p_cam`` (camera frame, m): the
    tangent cone's half-angle through the pinhole."""
    radius = diameter_m / 2.0
    dist2 = float(p_cam @ p_cam)
    return model.f_px * radius / math.sqrt(max(dist2 - radius * radius, 1e-12))


class DetectorFaults:
    """Seeded detector faults, one :meth:`frame` call per captured frame.

    Gilbert-Elliott drops: a two-state Markov chain per frame. In the good state a frame is
    dropped with ``dropout_probability`` and the chain enters the bad state with
    ``burst_probability``; in the bad state a frame is dropped with ``burst_drop_probability``
    and the chain leaves with 1 / ``burst_mean_frames`` (burst lengths are geometric with that
    mean). A false blob of ``false_blob_px`` appears anywhere in the frame with
    ``false_probability``; the detector reports one blob a frame, the larger. Every random
    number is drawn each frame, so the stream does not depend on the outcome."""

    def __init__(self, spec: CameraSpec, rng: np.random.Generator) -> None:
        self.spec = spec
        self._rng = rng
        self.bad = False  # in a drop burst
        self.frames = self.dropped = self.false_detections = self.too_small = 0

    def frame(self) -> tuple[bool, tuple[float, float] | None]:
        """Advance one frame: (drop this frame, false blob centre as fractions of width and
        height or None). The independent dropout of the good state is drawn by the camera."""
        spec = self.spec
        u = self._rng.random(4)
        self.frames += 1
        if self.bad:
            drop = bool(u[0] < spec.burst_drop_probability)
            if u[1] < 1.0 / spec.burst_mean_frames:
                self.bad = False
        else:
            drop = False
            if u[1] < spec.burst_probability:
                self.bad = True
        self.dropped += drop
        clutter = None
        if u[2] < spec.false_probability:
            clutter = (float(u[3]), float(self._rng.random()))
        else:
            self._rng.random()
        return drop, clutter

    def big_enough(self, diameter_px: float) -> bool:
        """Is a blob this wide (px) detected at all (``min_blob_px``, 0 = any size)?"""
        ok = diameter_px >= self.spec.min_blob_px
        self.too_small += not ok
        return ok


class SimCamera:
    def __init__(
        self,
        spec: CameraSpec,
        model: CameraModel,
        mode: str,
        rng: np.random.Generator,
        render_rng: np.random.Generator,
    ) -> None:
        if mode not in CAMERA_MODES:
            raise ValueError(f"unknown camera mode {mode!r}; choose one of {CAMERA_MODES}")
        self.spec = spec
        self.model = model
        self.mode = mode
        self._rng = rng
        self._pending: list[tuple[float, int, Detection]] = []
        self._count = 0
        self.renderer = FrameRenderer(model, render_rng) if mode == "rendered" else None
        self.detector = RedBalloonDetector() if mode == "rendered" else None
        self.last_frame: np.ndarray | None = None
        self.last_truth_px: tuple[float, float] | None = None
        self.frames = 0
        self.detections = 0
        # its own stream (spawned: the camera's stream is the same with or without faults)
        self.faults = DetectorFaults(spec, rng.spawn(1)[0])

    def capture(
        self,
        t_s: float,
        R_WC: np.ndarray,
        camera_pos_enu_m: np.ndarray,
        target_pos_enu_m: np.ndarray,
        target_diameter_m: float,
    ) -> None:
        """Take a frame at ``t_s`` and schedule its detection (if any) for delivery."""
        self.frames += 1
        spec = self.spec
        p_cam = R_WC.T @ (target_pos_enu_m - camera_pos_enu_m)
        self.last_truth_px = self.model.project(p_cam)
        # draw every random number each frame so the stream does not depend on the outcome
        dropped = self._rng.random() < spec.dropout_probability
        noise = self._rng.standard_normal(2) * spec.noise_px
        delay = spec.delay_s + spec.delay_jitter_s * float(self._rng.standard_normal())
        delay = min(max(delay, 0.5 * spec.delay_s), 2.0 * spec.delay_s + 1e-9)
        burst_drop, clutter = self.faults.frame()
        if self.mode == "rendered":
            frame = self.renderer.render(
                R_WC, camera_pos_enu_m, target_pos_enu_m, target_diameter_m
            )
            self.last_frame = frame
            det = self.detector.detect(frame, t_s)
        else:
            det = self._project(t_s, p_cam, target_diameter_m, noise)
        if det is not None and not self.faults.big_enough(max(det.bbox_px[2], det.bbox_px[3])):
            det = None
        if clutter is not None:
            false_det = self._false_blob(t_s, clutter)
            if det is None or false_det.area_px > det.area_px:
                self.faults.false_detections += 1
                det = false_det
        if det is None or dropped or burst_drop:
            return
        self.detections += 1
        self._count += 1
        heapq.heappush(self._pending, (t_s + delay, self._count, det))

    def _project(self, t_s, p_cam, diameter_m, noise) -> Detection | None:
        m = self.model
        uv = m.project(p_cam)
        if uv is None:
            return None
        r_px = apparent_radius_px(m, p_cam, diameter_m)
        u, v = uv
        # visible when at least part of the disc is in the frame
        if not (-r_px < u < m.width_px + r_px and -r_px < v < m.height_px + r_px):
            return None
        u += float(noise[0])
        v += float(noise[1])
        return Detection(
            capture_time_s=t_s,
            center_px=(u, v),
            bbox_px=(u - r_px, v - r_px, 2.0 * r_px, 2.0 * r_px),
            area_px=math.pi * r_px * r_px,
        )

    def _false_blob(self, t_s: float, where: tuple[float, float]) -> Detection:
        m, r = self.model, 0.5 * self.spec.false_blob_px
        u, v = where[0] * m.width_px, where[1] * m.height_px
        return Detection(
            capture_time_s=t_s,
            center_px=(u, v),
            bbox_px=(u - r, v - r, 2.0 * r, 2.0 * r),
            area_px=math.pi * r * r,
        )

    def deliver(self, t_s: float) -> list[Detection]:
        """Detections whose result is ready at ``t_s``, in arrival order."""
        out = []
        while self._pending and self._pending[0][0] <= t_s + 1e-12:
            out.append(heapq.heappop(self._pending)[2])
        return out
