"""Colour detector for a red balloon, behind the small :class:`Detector` interface so that a
learned detector can replace it.

Pipeline: HSV threshold on the two red hue bands -> external contours -> pick the blob that
looks most like a balloon (area x roundness) -> centre. A balloon cut by the frame edge is
recovered by fitting a circle to the part of its outline that is not on the edge, so the
centre stays right even when it lies outside the frame.

Region of interest (as trackers do): after a detection, the next frame is searched first in a
window around where the blob is predicted (the last centre moved on by the last frame-to-frame
image velocity, the last size plus a margin). The window's answer is used only when it is
*clean*: a blob was found and no mask pixel lies on a window side that is inside the frame, so
every blob in the window is whole and its statistics (outline, area, bounding box, centre) are
exactly those of the full-frame search. Otherwise, and every ``full_frame_every`` frames, the
whole frame is searched, so the window never loses a detection; what it can change is only
which blob wins when a larger red blob lies outside the window (it gates clutter, as a tracker
does, until the next full search).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from ..datatypes import Detection


class Detector(Protocol):
    def detect(self, frame_bgr: np.ndarray, capture_time_s: float) -> Detection | None:
        """Find the target in a BGR uint8 frame captured at ``capture_time_s``."""
        ...


@dataclass(frozen=True)
class RedBalloonConfig:
    min_saturation: int = 90
    min_value: int = 25  # low light still passes
    hue_band_deg: int = 12  # half width around red (0/180 in OpenCV's 0..180 hue)
    min_area_px: float = 8.0
    min_edge_arc_fraction: float = 0.15  # of the outline, needed for the edge circle fit
    # region of interest while tracking (roi = False: every frame searched whole)
    roi: bool = True
    roi_margin_px: float = 32.0  # around the predicted box, each side
    roi_growth: float = 0.25  # extra margin per px of the last blob's size, each side
    roi_max_gap_s: float = 0.25  # no window when the last detection is older than this
    full_frame_every: int = 30  # frames: a full search at least this often (0: never)


def min_redness(config: RedBalloonConfig) -> int | None:
    """A lower bound of R - max(G, B) over the colours in the mask (OpenCV's 8-bit HSV), or
    None when there is none to use. In the mask, H is within ``hue_band_deg`` (< 30) of red,
    so R is the largest channel, and |G - B| <= (band + 0.5) / 30 of diff = R - min(G, B)
    (H = 30 (G - B) / diff, rounded); S >= min_saturation makes diff >= V (S - 0.5) / 255
    with V = R >= min_value. One less than the floor of their product, at least 1 (R is the
    strict maximum: a tie gives H = 30 or 150). Checked over all 2^24 colours in the tests."""
    c = config
    if c.min_saturation < 1 or c.hue_band_deg >= 30:
        return None  # greys (S = 0) or green/blue-dominant hues may pass: no bound used
    bound = c.min_value * (c.min_saturation - 0.5) / 255.0 * (1.0 - (c.hue_band_deg + 0.5) / 30.0)
    return max(1, math.floor(bound) - 1)


@dataclass
class RoiStats:
    """How the frames were searched: ``windowed`` answered from the window alone, ``full``
    searched whole (no track, the periodic full search, or a fallback), ``fallbacks`` of those
    after a window that was not clean or held no blob."""

    windowed: int = 0
    full: int = 0
    fallbacks: int = 0


@dataclass
class _Track:
    time_s: float
    center_px: tuple[float, float]
    size_px: float  # larger side of the bounding box
    vel_px_s: tuple[float, float]
    frame_shape: tuple[int, int]


class RedBalloonDetector:
    def __init__(self, config: RedBalloonConfig | None = None) -> None:
        self.config = config or RedBalloonConfig()
        c = self.config
        if c.roi_margin_px < 0 or c.roi_growth < 0 or c.roi_max_gap_s < 0:
            raise ValueError("roi_margin_px, roi_growth and roi_max_gap_s must be >= 0")
        if c.full_frame_every < 0:
            raise ValueError("full_frame_every must be >= 0 (0: never)")
        self._lo1 = np.array([0, c.min_saturation, c.min_value], np.uint8)
        self._hi1 = np.array([c.hue_band_deg, 255, 255], np.uint8)
        self._lo2 = np.array([180 - c.hue_band_deg, c.min_saturation, c.min_value], np.uint8)
        self._hi2 = np.array([180, 255, 255], np.uint8)
        self._min_redness = min_redness(c)
        self._dilate_kernel = np.ones((3, 3), np.uint8)
        self._track: _Track | None = None
        self._since_full = 0
        self.stats = RoiStats()
        self.last_window_px: tuple[int, int, int, int] | None = None  # x0, y0, x1, y1

    def reset(self) -> None:
        """Forget the track: the next frame is searched whole."""
        self._track = None

    def mask(self, frame_bgr: np.ndarray) -> np.ndarray:
        hsv = cv2.cvtColor(frame_bgr, cv2.COLOR_BGR2HSV)
        return cv2.bitwise_or(
            cv2.inRange(hsv, self._lo1, self._hi1), cv2.inRange(hsv, self._lo2, self._hi2)
        )

    def detect(self, frame_bgr: np.ndarray, capture_time_s: float) -> Detection | None:
        if frame_bgr.ndim != 3 or frame_bgr.shape[2] != 3 or frame_bgr.dtype != np.uint8:
            raise ValueError("expected a BGR uint8 frame of shape (H, W, 3)")
        if not math.isfinite(capture_time_s):
            raise ValueError("capture_time_s must be finite")
        window = self.window(frame_bgr.shape[:2], capture_time_s)
        self.last_window_px = window
        if window is not None:
            det, clean = self.detect_in(frame_bgr, capture_time_s, window)
            if clean and det is not None:
                self._since_full += 1
                self.stats.windowed += 1
                self._update_track(det, frame_bgr.shape[:2])
                return det
            self.stats.fallbacks += 1
        self._since_full = 0
        self.stats.full += 1
        det, _ = self.detect_in(frame_bgr, capture_time_s, None)
        self._update_track(det, frame_bgr.shape[:2])
        return det

    def window(self, shape_hw: tuple[int, int], capture_time_s: float) -> tuple | None:
        """The window (x0, y0, x1, y1 px, end exclusive) to search first in a frame of this
        shape captured at ``capture_time_s``, or None to search it whole."""
        c, tr = self.config, self._track
        if not c.roi or tr is None or tr.frame_shape != tuple(shape_hw):
            return None
        dt = capture_time_s - tr.time_s
        if not (0.0 < dt <= c.roi_max_gap_s):
            return None
        if c.full_frame_every and self._since_full >= c.full_frame_every - 1:
            return None
        h, w = shape_hw
        half = self._half_window_px(tr.size_px)
        u = tr.center_px[0] + tr.vel_px_s[0] * dt
        v = tr.center_px[1] + tr.vel_px_s[1] * dt
        x0, x1 = max(math.floor(u - half), 0), min(math.ceil(u + half), w)
        y0, y1 = max(math.floor(v - half), 0), min(math.ceil(v + half), h)
        if x1 - x0 < 3 or y1 - y0 < 3:  # predicted off the frame
            return None
        if x0 == 0 and y0 == 0 and x1 == w and y1 == h:  # the whole frame anyway
            return None
        return x0, y0, x1, y1

    def _half_window_px(self, size_px: float) -> float:
        c = self.config
        return 0.5 * size_px + c.roi_growth * size_px + c.roi_margin_px

    def _update_track(self, det: Detection | None, shape_hw: tuple[int, int]) -> None:
        """Keep the detection as the track; its image velocity from the previous one, unless
        the blob jumped farther than a window (another blob, or the target found again)."""
        if det is None:
            self._track = None
            return
        tr = self._track
        vel = (0.0, 0.0)
        if tr is not None:
            dt = det.capture_time_s - tr.time_s
            du = det.center_px[0] - tr.center_px[0]
            dv = det.center_px[1] - tr.center_px[1]
            half = self._half_window_px(tr.size_px)
            if 0.0 < dt <= self.config.roi_max_gap_s and max(abs(du), abs(dv)) <= half:
                vel = (du / dt, dv / dt)
        size = max(det.bbox_px[2], det.bbox_px[3])
        self._track = _Track(det.capture_time_s, det.center_px, size, vel, tuple(shape_hw))

    def red_box(self, frame_bgr: np.ndarray) -> tuple[int, int, int, int] | None:
        """The box (x0, y0, x1, y1 px, end exclusive) around every pixel whose R - max(G, B)
        reaches :func:`min_redness`, grown by one pixel (so its sides inside the frame hold
        no mask pixel), or None when there is none: the mask is empty outside it."""
        redness = cv2.subtract(frame_bgr[:, :, 2], cv2.max(frame_bgr[:, :, 0], frame_bgr[:, :, 1]))
        if self._min_redness > 1:
            redness = cv2.threshold(redness, self._min_redness - 1, 255, cv2.THRESH_BINARY)[1]
        x, y, bw, bh = cv2.boundingRect(redness)
        if bw == 0:
            return None
        h, w = frame_bgr.shape[:2]
        return max(x - 1, 0), max(y - 1, 0), min(x + bw + 1, w), min(y + bh + 1, h)

    def detect_in(
        self,
        frame_bgr: np.ndarray,
        capture_time_s: float,
        window: tuple[int, int, int, int] | None,
    ) -> tuple[Detection | None, bool]:
        """Search ``window`` (x0, y0, x1, y1 px, end exclusive; None: the whole frame) and
        return (detection, clean). Clean: no mask pixel on a window side inside the frame, so
        each blob found is whole and its figures are those of the full-frame search. Not clean
        returns (None, False) at once."""
        h, w = frame_bgr.shape[:2]
        if window is None and self._min_redness is not None:
            # only the box around every pixel red enough to be in the mask needs the mask
            box = self.red_box(frame_bgr)
            if box is None:
                return None, True
            det, clean = self.detect_in(frame_bgr, capture_time_s, box)
            if clean:  # always (the box's inner sides hold no mask pixel); else search all
                return det, True
        if window is None:
            ox, oy = 0, 0
            mask = self.mask(frame_bgr)
        else:
            ox, oy, x1, y1 = window
            mask = self.mask(frame_bgr[oy:y1, ox:x1])
            if (
                (ox > 0 and mask[:, 0].any())
                or (oy > 0 and mask[0].any())
                or (x1 < w and mask[:, -1].any())
                or (y1 < h and mask[-1].any())
            ):
                return None, False
        contours, _ = cv2.findContours(
            mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE, offset=(ox, oy)
        )
        best, best_score = None, 0.0
        for cnt in contours:
            area = cv2.contourArea(cnt) + 0.5 * len(cnt)  # outline pixels count as half
            if area < self.config.min_area_px:
                continue
            perim = max(cv2.arcLength(cnt, True), 1e-6)
            roundness = min(4.0 * math.pi * area / perim**2, 1.0)
            score = area * roundness
            if score > best_score:
                best, best_score = cnt, score
        if best is None:
            return None, True
        x, y, bw, bh = cv2.boundingRect(best)
        touches_edge = x <= 0 or y <= 0 or x + bw >= w or y + bh >= h
        center = self._edge_circle_centre(best, w, h) if touches_edge else None
        if center is None:
            center = self._weighted_centroid(frame_bgr, mask, ox, oy, x, y, bw, bh)
        area = float(cv2.contourArea(best) + 0.5 * len(best))
        det = Detection(
            capture_time_s=capture_time_s,
            center_px=center,
            bbox_px=(float(x), float(y), float(bw), float(bh)),
            area_px=area,
            score=float(best_score / max(area, 1.0)),
        )
        return det, True

    def _weighted_centroid(self, frame, mask, ox, oy, x, y, bw, bh) -> tuple[float, float]:
        # Sub-pixel centre: the mask grown by one pixel keeps the anti-aliased rim, weighted by
        # redness (R - max(G, B)) so partly covered rim pixels count partly. ``mask`` covers
        # the frame from (ox, oy); the box and its one-pixel ring lie inside it.
        h, w = frame.shape[:2]
        x0, y0 = max(x - 1, 0), max(y - 1, 0)
        x1, y1 = min(x + bw + 1, w), min(y + bh + 1, h)
        b, g, r = cv2.split(frame[y0:y1, x0:x1])
        red = cv2.subtract(r, cv2.max(b, g))  # R - max(G, B) clipped at 0, exact in uint8
        grown = cv2.dilate(mask[y0 - oy : y1 - oy, x0 - ox : x1 - ox], self._dilate_kernel)
        wgt = cv2.bitwise_and(red, red, mask=grown).astype(np.float32)
        total = float(wgt.sum())
        if total <= 0.0:
            return x + bw / 2.0, y + bh / 2.0
        # the products and sums of np.mgrid's grids, from broadcast rows and columns
        xs = np.arange(x0, x1)[None, :]
        ys = np.arange(y0, y1)[:, None]
        # +0.5: pixel (i, j) covers [j, j+1) x [i, i+1); its centre is at j + 0.5
        return float((wgt * xs).sum() / total) + 0.5, float((wgt * ys).sum() / total) + 0.5

    def _edge_circle_centre(self, cnt: np.ndarray, w: int, h: int) -> tuple[float, float] | None:
        pts = cnt.reshape(-1, 2).astype(np.float64)
        inner = pts[(pts[:, 0] > 1) & (pts[:, 0] < w - 2) & (pts[:, 1] > 1) & (pts[:, 1] < h - 2)]
        if len(inner) < max(8, self.config.min_edge_arc_fraction * len(pts)):
            return None
        # algebraic (Kasa) circle fit: x^2 + y^2 + D x + E y + F = 0, on pixel-centre coordinates
        xs, ys = inner[:, 0] + 0.5, inner[:, 1] + 0.5
        A = np.column_stack([xs, ys, np.ones_like(xs)])
        b = -(xs * xs + ys * ys)
        sol, *_ = np.linalg.lstsq(A, b, rcond=None)
        cx, cy = -sol[0] / 2.0, -sol[1] / 2.0
        r2 = cx * cx + cy * cy - sol[2]
        if not (np.isfinite(cx) and np.isfinite(cy)) or r2 <= 0.0:
            return None
        return float(cx), float(cy)
