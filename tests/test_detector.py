"""Red-balloon detector on rendered frames."""

import numpy as np
import pytest

from groundstation.sim.render import GROUND_BGR, SKY_BGR, draw_balloon
from onboard.perception import RedBalloonDetector

DET = RedBalloonDetector()


def _sky(noise_seed=None, brightness=1.0):
    frame = np.empty((480, 640, 3), np.uint8)
    frame[:] = SKY_BGR
    frame[300:] = GROUND_BGR
    if noise_seed is not None:
        rng = np.random.default_rng(noise_seed)
        noisy = frame.astype(np.int16) + rng.integers(-3, 4, frame.shape)
        frame = np.clip(noisy, 0, 255).astype(np.uint8)
    if brightness != 1.0:
        frame = np.clip(frame * brightness, 0, 255).astype(np.uint8)
    return frame


def _error(det, u, v):
    return float(np.hypot(det.center_px[0] - u, det.center_px[1] - v))


@pytest.mark.parametrize("radius", [3.0, 4.5, 8.0, 20.0, 60.0])
def test_centre_within_2px_when_at_least_6px_across(radius):
    rng = np.random.default_rng(int(radius * 10))
    worst = 0.0
    for i in range(10):
        u, v = rng.uniform(80, 560), rng.uniform(80, 400)
        frame = _sky(noise_seed=i)
        draw_balloon(frame, u, v, radius)
        det = DET.detect(frame, capture_time_s=1.25)
        assert det is not None
        assert det.capture_time_s == 1.25
        worst = max(worst, _error(det, u, v))
        bx, by, bw, bh = det.bbox_px
        assert bx <= u <= bx + bw and by <= v <= by + bh
    assert worst <= 2.0, worst


def test_empty_sky_and_ground_give_nothing():
    assert DET.detect(_sky(noise_seed=3), 0.0) is None


def test_partial_occlusion_at_frame_edge():
    for u, v, r in ((8.0, 200.0, 30.0), (630.0, 470.0, 25.0), (-10.0, 100.0, 40.0)):
        frame = _sky(noise_seed=1)
        draw_balloon(frame, u, v, r)
        det = DET.detect(frame, 0.0)
        assert det is not None
        assert _error(det, u, v) <= 2.0, (u, v, det.center_px)


def test_low_light():
    frame = _sky(noise_seed=2)
    draw_balloon(frame, 250.3, 180.7, 12.0)
    dark = np.clip(frame * 0.25, 0, 255).astype(np.uint8)
    det = DET.detect(dark, 0.0)
    assert det is not None and _error(det, 250.3, 180.7) <= 2.0


def test_second_smaller_red_object_is_ignored():
    frame = _sky(noise_seed=4)
    draw_balloon(frame, 400.0, 150.0, 15.0)
    frame[350:362, 100:130] = (30, 30, 200)  # a red box, 12 x 30 px
    draw_balloon(frame, 200.0, 100.0, 5.0)  # a small red disc
    det = DET.detect(frame, 0.0)
    assert det is not None and _error(det, 400.0, 150.0) <= 2.0


def test_rejects_non_bgr_input():
    with pytest.raises(ValueError, match="BGR uint8"):
        DET.detect(np.zeros((480, 640), np.uint8), 0.0)
