"""Colour detector for a red balloon, behind the small :class:`Detector` interface so that a
learned detector can replace it.

Pipeline: HSV threshold on the two red hue bands -> external contours -> pick the blob that
looks most like a balloon (area x roundness) -> centre. A balloon cut by the frame edge is
recovered by fitting a circle to the part of its outline that is not on the edge, so the
centre stays right even when it lies outside the frame.
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


class RedBalloonDetector:
    def __init__(self, config: RedBalloonConfig | None = None) -> None:
        self.config = config or RedBalloonConfig()
        c = self.config
        self._lo1 = np.array([0, c.min_saturation, c.min_value], np.uint8)
        self._hi1 = np.array([c.hue_band_deg, 255, 255], np.uint8)
        self._lo2 = np.array([180 - c.hue_band_deg, c.min_saturation, c.min_value], np.uint8)
        self._hi2 = np.array([180, 255, 255], np.uint8)

    def mask(self, frame_bgr: np.ndarray) -> np.ndarray:
        hsv = cv2.cvtColor(frame_bgr, cv2.COLOR_BGR2HSV)
        return cv2.bitwise_or(
            cv2.inRange(hsv, self._lo1, self._hi1), cv2.inRange(hsv, self._lo2, self._hi2)
        )

    def detect(self, frame_bgr: np.ndarray, capture_time_s: float) -> Detection | None:
        if frame_bgr.ndim != 3 or frame_bgr.shape[2] != 3 or frame_bgr.dtype != np.uint8:
            raise ValueError("expected a BGR uint8 frame of shape (H, W, 3)")
        mask = self.mask(frame_bgr)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
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
            return None
        h, w = mask.shape
        x, y, bw, bh = cv2.boundingRect(best)
        touches_edge = x <= 0 or y <= 0 or x + bw >= w or y + bh >= h
        center = self._edge_circle_centre(best, w, h) if touches_edge else None
        if center is None:
            center = self._weighted_centroid(frame_bgr, mask, x, y, bw, bh)
        area = float(cv2.contourArea(best) + 0.5 * len(best))
        return Detection(
            capture_time_s=capture_time_s,
            center_px=center,
            bbox_px=(float(x), float(y), float(bw), float(bh)),
            area_px=area,
            score=float(best_score / max(area, 1.0)),
        )

    @staticmethod
    def _weighted_centroid(frame, mask, x, y, bw, bh) -> tuple[float, float]:
        # Sub-pixel centre: the mask grown by one pixel keeps the anti-aliased rim, weighted by
        # redness (R - max(G, B)) so partly covered rim pixels count partly.
        x0, y0 = max(x - 1, 0), max(y - 1, 0)
        x1, y1 = min(x + bw + 1, mask.shape[1]), min(y + bh + 1, mask.shape[0])
        roi = frame[y0:y1, x0:x1].astype(np.float32)
        red = np.clip(roi[:, :, 2] - np.maximum(roi[:, :, 0], roi[:, :, 1]), 0.0, None)
        grown = cv2.dilate(mask[y0:y1, x0:x1], np.ones((3, 3), np.uint8)) > 0
        wgt = np.where(grown, red, 0.0)
        total = float(wgt.sum())
        if total <= 0.0:
            return x + bw / 2.0, y + bh / 2.0
        ys, xs = np.mgrid[y0:y1, x0:x1]
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
