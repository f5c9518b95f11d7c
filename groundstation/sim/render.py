"""Renders the simulated camera's frame: sky, ground below the true horizon for the current
attitude, and the balloon as a shaded disc of its true apparent size (sub-pixel, anti-aliased),
plus seeded sensor noise."""

from __future__ import annotations

import math

import cv2
import numpy as np

from onboard.camera_model import CameraModel

SKY_BGR = (225, 190, 150)
GROUND_BGR = (70, 115, 85)
BALLOON_DARK_BGR = (25, 25, 150)
BALLOON_MID_BGR = (40, 40, 205)
BALLOON_LIGHT_BGR = (120, 120, 250)
_COLOURS = (SKY_BGR, GROUND_BGR, BALLOON_DARK_BGR, BALLOON_MID_BGR, BALLOON_LIGHT_BGR)
_SHIFT = 4  # cv2 sub-pixel bits
_SCALE = 1 << _SHIFT


class FrameRenderer:
    def __init__(self, camera: CameraModel, rng: np.random.Generator, noise_level: int = 3) -> None:
        self.camera = camera
        w, h = camera.width_px, camera.height_px
        self._sky = np.empty((h, w, 3), np.uint8)
        self._sky[:] = SKY_BGR
        self._corner_list = [(0.0, 0.0), (float(w), 0.0), (float(w), float(h)), (0.0, float(h))]
        self._rng = rng
        # a few noise frames, picked at random each time: seeded, and cheap per frame
        self._noise_up = [uniform_uint8(rng, noise_level, (h, w, 3)) for _ in range(3)]
        self._noise_down = [uniform_uint8(rng, noise_level, (h, w, 3)) for _ in range(3)]
        # The frame is (frame + up[k]) - down[k + 1], each saturating. Every colour drawn (and
        # every anti-aliased mix of two) lies in [lo, hi]; when noise_level <= lo and
        # hi + noise_level <= 255 neither step saturates, so it equals one wrapping uint8
        # addition of up[k] - down[k + 1] (mod 256): one pass over the frame instead of two.
        n = len(self._noise_up)
        channels = [c for col in _COLOURS for c in col]
        self._one_pass = noise_level <= min(channels) and max(channels) + noise_level <= 255
        self._noise_net = [  # uint8 arithmetic wraps: the difference mod 256
            np.subtract(self._noise_up[k], self._noise_down[(k + 1) % n]) for k in range(n)
        ]

    def _ground_polygon(self, R_WC: np.ndarray) -> np.ndarray | None:
        """Image region whose rays point below the horizon (world z < 0); vertices in 1/16 px.
        Plain floats: the same IEEE arithmetic as on numpy scalars, without their overhead."""
        cam = self.camera
        r0, r1, r2 = R_WC[2, :].tolist()
        f, cu, cv_ = cam.f_px, cam.cu_px, cam.cv_px
        pts = self._corner_list
        g = [r0 * (x - cu) / f + r1 * (y - cv_) / f + r2 for x, y in pts]
        out = []
        for i in range(4):
            (ax, ay), (bx, by) = pts[i], pts[(i + 1) % 4]
            ga, gb = g[i], g[(i + 1) % 4]
            if ga < 0.0:
                out.append((ax, ay))
            if (ga < 0.0) != (gb < 0.0):
                s = ga / (ga - gb)
                out.append((ax + s * (bx - ax), ay + s * (by - ay)))
        if len(out) < 3:
            return None
        return np.array([[round(x * _SCALE), round(y * _SCALE)] for x, y in out], np.int32)

    def render(
        self,
        R_WC: np.ndarray,
        camera_pos_enu_m: np.ndarray,
        target_pos_enu_m: np.ndarray,
        target_diameter_m: float,
        brightness: float = 1.0,
        clutter_px: tuple[float, float, float] | None = None,
        target_visible: bool = True,
    ) -> np.ndarray:
        """The frame; ``clutter_px`` (u, v, diameter) adds a false red blob, and
        ``target_visible=False`` leaves the balloon out (too small for the detector)."""
        frame = self._sky.copy()
        poly = self._ground_polygon(R_WC)
        if poly is not None:
            cv2.fillPoly(frame, [poly], GROUND_BGR, cv2.LINE_AA, _SHIFT)
        if target_visible:
            p_cam = R_WC.T @ (target_pos_enu_m - camera_pos_enu_m)
            self._draw_balloon(frame, p_cam, target_diameter_m)
        if clutter_px is not None:
            draw_balloon(frame, clutter_px[0], clutter_px[1], 0.5 * clutter_px[2])
        if brightness != 1.0:
            frame = cv2.convertScaleAbs(frame, alpha=brightness)
        k = int(self._rng.integers(0, len(self._noise_up)))
        if self._one_pass and brightness == 1.0:
            np.add(frame, self._noise_net[k], out=frame)  # wraps, never past 0 or 255 here
        else:
            cv2.add(frame, self._noise_up[k], dst=frame)
            cv2.subtract(frame, self._noise_down[(k + 1) % len(self._noise_down)], dst=frame)
        return frame

    def _draw_balloon(self, frame: np.ndarray, p_cam: np.ndarray, diameter_m: float) -> None:
        cam = self.camera
        radius = diameter_m / 2.0
        dist2 = float(p_cam @ p_cam)
        z = float(p_cam[2])
        if z <= 0.02 or dist2 <= radius * radius:
            return
        r_px = cam.f_px * radius / math.sqrt(dist2 - radius * radius)
        u = cam.cu_px + cam.f_px * float(p_cam[0]) / z
        v = cam.cv_px + cam.f_px * float(p_cam[1]) / z
        u, v, r_px = cam.disc_through_lens(u, v, r_px)  # the lens's distortion
        lim = 4.0 * (cam.width_px + cam.height_px)
        if abs(u) > lim + r_px or abs(v) > lim + r_px or r_px > 1e5:
            return
        draw_balloon(frame, u, v, r_px)


def uniform_uint8(rng: np.random.Generator, high: int, shape: tuple[int, ...]) -> np.ndarray:
    """``rng.integers(0, high + 1, shape, dtype=np.uint8)``, the same numbers and the same use
    of the stream, about 10 times cheaper when ``high + 1`` is a power of two from 2 to 128:
    numpy then takes each value as the top bits of one byte of its 32-bit draws (Lemire's
    method never rejects), and ``rng.bytes`` hands out those same bytes (tests check both)."""
    n = high + 1
    if not (1 < n <= 128 and n & (n - 1) == 0):
        return rng.integers(0, n, shape, dtype=np.uint8)
    count = math.prod(shape)
    raw = np.frombuffer(rng.bytes(count), np.uint8)
    return (raw >> (9 - n.bit_length())).reshape(shape)


def draw_balloon(frame: np.ndarray, u: float, v: float, r_px: float) -> None:
    """A shaded red disc centred at (u, v) px with radius r_px (lit from above-left)."""

    def circle(cu, cv_, rr, colour):
        cv2.circle(
            frame,
            (round(cu * _SCALE), round(cv_ * _SCALE)),
            max(round(rr * _SCALE), 1),
            colour,
            -1,
            cv2.LINE_AA,
            _SHIFT,
        )

    # pixel (i, j) spans [j, j+1): cv2 draws in pixel-centre coordinates, hence the -0.5
    u0, v0 = u - 0.5, v - 0.5
    circle(u0, v0, r_px, BALLOON_DARK_BGR)
    if r_px >= 3.0:
        circle(u0 - 0.15 * r_px, v0 - 0.15 * r_px, 0.75 * r_px, BALLOON_MID_BGR)
        circle(u0 - 0.35 * r_px, v0 - 0.35 * r_px, 0.2 * r_px, BALLOON_LIGHT_BGR)
