"""The simulated strapdown camera and detection pipeline.

Frames are captured at the camera rate. ``projected`` mode projects the target analytically
through the true lens (pinhole, then Brown-Conrady distortion) and reports what a blob
detector sees: the visible part of the disc, its size and centre with noise; ``rendered``
mode draws a real frame through the same lens and runs the onboard detector on it. Both
apply the same capture-to-result delay with jitter and random dropouts, and deliver each
detection stamped with its capture time when its delay has passed.

:class:`DetectorFaults` adds what a real detector does (on by default, each switched off by a
``[camera]`` key set to 0): a minimum blob size (a range limit: the projected camera would
otherwise report a 0.06 px balloon), false red blobs (clutter) and bursty frame drops (a
Gilbert-Elliott two-state channel).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence

import numpy as np

from onboard.camera_model import CameraModel, pixel_of
from onboard.datatypes import Detection
from onboard.jit import kernel
from onboard.perception import RedBalloonDetector

from ..scenario import CAMERA_MODES, CameraSpec
from .render import FrameRenderer


@kernel(
    "UniTuple(float64, 4)(float64[:, :], float64, float64, float64, float64, float64, float64,"
    " float64, float64, float64, float64)",
    uses=(pixel_of,),
)
def sphere_image(
    R_WC: np.ndarray,
    c0: float,
    c1: float,
    c2: float,
    t0: float,
    t1: float,
    t2: float,
    diameter_m: float,
    f_px: float,
    cu_px: float,
    cv_px: float,
) -> tuple[float, float, float, float]:
    """How a pinhole camera at c (ENU, m) with attitude ``R_WC`` (camera -> ENU) sees a sphere
    of ``diameter_m`` centred at t (compiled): (1 if its centre is in front of the camera else
    0, the centre's pixel (u, v) (:func:`~onboard.camera_model.pixel_of`; nan behind), its
    image radius (px): the tangent cone's half-angle through the pinhole). The camera-frame
    point R_WC^T (t - c) is summed in index order (not numpy's BLAS: its rounding depends on
    the CPU)."""
    d0, d1, d2 = t0 - c0, t1 - c1, t2 - c2
    p0 = R_WC[0, 0] * d0 + R_WC[1, 0] * d1 + R_WC[2, 0] * d2
    p1 = R_WC[0, 1] * d0 + R_WC[1, 1] * d1 + R_WC[2, 1] * d2
    p2 = R_WC[0, 2] * d0 + R_WC[1, 2] * d1 + R_WC[2, 2] * d2
    ahead, u, v = pixel_of(p0, p1, p2, f_px, cu_px, cv_px)
    radius = diameter_m / 2.0
    dist2 = p0 * p0 + p1 * p1 + p2 * p2
    return ahead, u, v, f_px * radius / math.sqrt(max(dist2 - radius * radius, 1e-12))


def sphere_in_view(
    model: CameraModel,
    R_WC: np.ndarray,
    camera_pos_enu_m: np.ndarray,
    target_pos_enu_m: np.ndarray,
    diameter_m: float,
) -> tuple[tuple[float, float] | None, float]:
    """:func:`sphere_image` for ``model``: (the centre's pixel or None behind the camera, the
    image radius in px)."""
    c0, c1, c2 = camera_pos_enu_m
    t0, t1, t2 = target_pos_enu_m
    ahead, u, v, r_px = sphere_image(
        R_WC, c0, c1, c2, t0, t1, t2, diameter_m, model.f_px, model.cu_px, model.cv_px
    )
    return ((u, v) if ahead else None), r_px


def centre_noise_px(area_px: float, floor_px: float, k_px: float) -> float:
    """1-sigma noise per axis of a blob's centroid (px): ``max(floor, k / sqrt(r))`` with r
    the radius of a disc of ``area_px``. A thresholded blob's centroid moves with the
    boundary pixels it gains or loses: about 2 pi r of them, each off by up to a pixel, each
    moving the mean of pi r^2 pixels by ~r / (pi r^2), so the error grows as r^(-1/2) as the
    blob shrinks; the floor is what a large blob keeps (shading, the colour threshold,
    motion blur)."""
    r = math.sqrt(max(area_px, 1e-12) / math.pi)
    return max(floor_px, k_px / math.sqrt(r))


_SLICES = 64  # rows of the numerical clip of a disc crossing the frame's edge


def visible_disc(
    u: float, v: float, r: float, width_px: float, height_px: float
) -> tuple[float, float, float, tuple[float, float, float, float]] | None:
    """The part of the disc (centre (u, v), radius r; px) inside the frame [0, w] x [0, h]:
    (its area, centroid u and v, bounding box (x, y, width, height)), None if no part is
    inside. A disc inside the frame is exact; one crossing an edge is integrated over
    ``_SLICES`` rows (chords clipped to the frame)."""
    x0, x1 = max(u - r, 0.0), min(u + r, width_px)
    y0, y1 = max(v - r, 0.0), min(v + r, height_px)
    if not (x0 < x1 and y0 < y1):
        return None
    if x0 == u - r and x1 == u + r and y0 == v - r and y1 == v + r:
        return math.pi * r * r, u, v, (u - r, v - r, 2.0 * r, 2.0 * r)
    dy = (y1 - y0) / _SLICES
    y = y0 + dy * (np.arange(_SLICES) + 0.5)
    h = np.sqrt(np.maximum(r * r - (y - v) ** 2, 0.0))
    a, b = np.maximum(u - h, 0.0), np.minimum(u + h, width_px)
    length = np.maximum(b - a, 0.0)
    area = float(length.sum()) * dy
    if not area > 0.0:
        return None
    cu = float((length * 0.5 * (a + b)).sum()) * dy / area
    cv = float((length * y).sum()) * dy / area
    # the box: the widest chord within the visible rows (at the centre's row if visible)
    dv = 0.0 if y0 <= v <= y1 else min(abs(y0 - v), abs(y1 - v))
    h_max = math.sqrt(max(r * r - dv * dv, 0.0))
    bx0, bx1 = max(u - h_max, 0.0), min(u + h_max, width_px)
    return area, cu, cv, (bx0, y0, bx1 - bx0, y1 - y0)


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
        u0, u1, u2, u3 = self._rng.random(4).tolist()
        self.frames += 1
        if self.bad:
            drop = u0 < spec.burst_drop_probability
            if u1 < 1.0 / spec.burst_mean_frames:
                self.bad = False
        else:
            drop = False
            if u1 < spec.burst_probability:
                self.bad = True
        self.dropped += drop
        clutter = None
        if u2 < spec.false_probability:
            clutter = (u3, self._rng.random())
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
        self._size_rng = rng.spawn(1)[0]  # the blob size's noise

    def capture(
        self,
        t_s: float,
        R_WC: np.ndarray,
        camera_pos_enu_m: Sequence[float],
        target_pos_enu_m: Sequence[float],
        target_diameter_m: float,
    ) -> None:
        """Take a frame at ``t_s`` and schedule its detection (if any) for delivery (the
        positions as 3-vectors, ENU m)."""
        self.frames += 1
        spec = self.spec
        uv, r_px = sphere_in_view(
            self.model, R_WC, camera_pos_enu_m, target_pos_enu_m, target_diameter_m
        )
        if uv is not None:
            u, v, r_px = self.model.disc_through_lens(uv[0], uv[1], r_px)
            uv = (u, v)
        self.last_truth_px = uv
        # draw every random number each frame so the stream does not depend on the outcome
        dropped = self._rng.random() < spec.dropout_probability
        n0, n1 = self._rng.standard_normal(2).tolist()
        noise = (n0, n1, float(self._size_rng.standard_normal()))
        delay = spec.delay_s + spec.delay_jitter_s * float(self._rng.standard_normal())
        delay = min(max(delay, 0.5 * spec.delay_s), 2.0 * spec.delay_s + 1e-9)
        burst_drop, clutter = self.faults.frame()
        if self.mode == "rendered":
            frame = self.renderer.render(
                R_WC, np.asarray(camera_pos_enu_m), np.asarray(target_pos_enu_m), target_diameter_m
            )
            self.last_frame = frame
            det = self.detector.detect(frame, t_s)
        else:
            det = self._project(t_s, uv, r_px, noise)
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

    def _project(self, t_s, uv, r_px, noise) -> Detection | None:
        """The detection of the target imaged at pixel ``uv`` (through the lens; None: behind
        the camera) with radius ``r_px``, as a blob detector reports it: the radius with its
        noise, the part of the disc inside the frame (its centroid, area and box), the
        centroid with noise growing as the blob shrinks (:func:`centre_noise_px`); None when no
        part of it is in the frame. ``noise``: three standard normals (u, v, radius)."""
        if uv is None:
            return None
        spec, m = self.spec, self.model
        r_true = r_px
        r_px = r_true + math.hypot(spec.size_noise_px, spec.size_noise_rel * r_true) * noise[2]
        if not r_px > 0.0:
            return None
        seen = visible_disc(uv[0], uv[1], r_px, m.width_px, m.height_px)
        if seen is None:
            return None
        area, u, v, bbox = seen
        sigma = centre_noise_px(area, spec.noise_px, spec.centre_noise_k_px)
        u += noise[0] * sigma
        v += noise[1] * sigma
        return Detection(capture_time_s=t_s, center_px=(u, v), bbox_px=bbox, area_px=area)

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
