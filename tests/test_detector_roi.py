"""The detector's region-of-interest search: while it tracks, a window around the
predicted blob is searched first; its answer equals the full-frame search's whenever it is
used, and the full frame is searched whenever the window is not clean or holds no blob."""

import dataclasses

import cv2
import numpy as np
import pytest

from groundstation.scenario import load_scenario, parse_overrides, with_overrides
from groundstation.sim.render import GROUND_BGR, SKY_BGR, draw_balloon
from groundstation.sim.simulation import Simulation
from onboard.perception import RedBalloonConfig, RedBalloonDetector
from onboard.perception.detector import min_redness

FRAME_S = 1.0 / 30.0


def _frame(balloons, noise_seed=0, boxes=()):
    """Sky over ground with seeded noise; ``balloons`` (u, v, r px), ``boxes`` red
    rectangles (x0, y0, x1, y1 px)."""
    frame = np.empty((480, 640, 3), np.uint8)
    frame[:] = SKY_BGR
    frame[300:] = GROUND_BGR
    for u, v, r in balloons:
        draw_balloon(frame, u, v, r)
    for x0, y0, x1, y1 in boxes:
        frame[y0:y1, x0:x1] = (30, 30, 200)
    rng = np.random.default_rng(noise_seed)
    noisy = frame.astype(np.int16) + rng.integers(-3, 4, frame.shape)
    return np.clip(noisy, 0, 255).astype(np.uint8)


def _full():
    return RedBalloonDetector(RedBalloonConfig(roi=False))


def _track(det, u=300.0, v=200.0, r=10.0, frames=2):
    """Detect a balloon standing at (u, v) for ``frames`` frames (t = 0, 1/30, ...)."""
    for i in range(frames):
        assert det.detect(_frame([(u, v, r)], noise_seed=100 + i), i * FRAME_S) is not None
    return frames * FRAME_S  # the next frame's time


def test_target_inside_the_window_gives_the_full_frame_figures():
    roi, full = RedBalloonDetector(), _full()
    # a balloon drifting 6 px a frame and growing, as in a closing sortie
    for i in range(25):
        frame = _frame([(200.0 + 6.3 * i, 150.0 + 2.1 * i, 6.0 + 0.4 * i)], noise_seed=i)
        a, b = roi.detect(frame, i * FRAME_S), full.detect(frame, i * FRAME_S)
        assert a is not None and a == b  # centre, box, area and score bit for bit
    assert roi.stats.windowed == 24 and roi.stats.full == 1 and roi.stats.fallbacks == 0
    x0, y0, x1, y1 = roi.last_window_px
    assert (x1 - x0) * (y1 - y0) < 0.1 * 640 * 480  # searched a small part of the frame


def test_the_window_follows_the_predicted_position():
    det = RedBalloonDetector()
    det.detect(_frame([(300.0, 200.0, 8.0)]), 0.0)
    det.detect(_frame([(310.0, 196.0, 8.0)], 1), FRAME_S)  # moving +10, -4 px a frame
    x0, y0, x1, y1 = det.window((480, 640), 2 * FRAME_S)
    cfg = det.config
    size = det.detect(_frame([(320.0, 192.0, 8.0)], 2), 2 * FRAME_S).bbox_px[2]
    assert (x0 + x1) / 2 == pytest.approx(320.0, abs=1.5)
    assert (y0 + y1) / 2 == pytest.approx(192.0, abs=1.5)
    half = 0.5 * size + cfg.roi_growth * size + cfg.roi_margin_px
    assert (x1 - x0) / 2 == pytest.approx(half, abs=1.5)


def test_target_outside_the_window_falls_back_to_the_full_frame():
    roi, full = RedBalloonDetector(), _full()
    t = _track(roi, 150.0, 120.0)
    frame = _frame([(520.0, 380.0, 10.0)], noise_seed=7)  # jumped far outside the window
    x0, y0, x1, y1 = roi.window((480, 640), t)
    assert not (x0 <= 520 < x1 and y0 <= 380 < y1)
    a = roi.detect(frame, t)
    assert a is not None and a == full.detect(frame, t)
    assert roi.stats.fallbacks == 1
    # the track moved there: the next frame is searched in a window around it
    frame = _frame([(521.0, 381.0, 10.0)], noise_seed=8)
    assert roi.detect(frame, t + FRAME_S) == full.detect(frame, t + FRAME_S)
    assert roi.stats.windowed == 2 and roi.stats.fallbacks == 1


@pytest.mark.parametrize("side", ["left", "right", "top", "bottom"])
def test_target_straddling_the_window_edge_is_measured_whole(side):
    roi, full = RedBalloonDetector(), _full()
    t = _track(roi, 320.0, 200.0, 10.0)
    x0, y0, x1, y1 = roi.window((480, 640), t)
    # a big balloon centred on the window's side: half of it lies outside the window
    u, v = {"left": (x0, 200.0), "right": (x1, 200.0), "top": (320.0, y0), "bottom": (320.0, y1)}[
        side
    ]
    frame = _frame([(u, v, 30.0)], noise_seed=9)
    a, b = roi.detect(frame, t), full.detect(frame, t)
    assert a is not None and a == b
    assert a.area_px > 0.9 * np.pi * 30.0**2  # the whole disc, not the window's part
    assert roi.stats.fallbacks == 1 and roi.stats.windowed == 1


def test_a_window_without_a_blob_searches_the_frame_and_nothing_resets_the_track():
    roi = RedBalloonDetector()
    t = _track(roi)
    assert roi.detect(_frame([], noise_seed=3), t) is None
    assert roi.stats.fallbacks == 1
    assert roi.window((480, 640), t + FRAME_S) is None  # no track: whole frames
    assert roi.detect(_frame([(100.0, 100.0, 9.0)], 4), t + FRAME_S) is not None
    assert roi.stats.full == 2 + 1  # the first frame, the fallback, the reacquisition


def test_no_window_for_an_old_track_a_new_stream_or_another_frame_size():
    roi = RedBalloonDetector()
    t = _track(roi)
    assert roi.window((480, 640), t) is not None
    assert roi.window((480, 640), t + 1.0) is None  # older than roi_max_gap_s
    assert roi.window((480, 640), t - FRAME_S) is None  # time did not advance: a new stream
    assert roi.window((240, 320), t) is None
    roi.reset()
    assert roi.window((480, 640), t) is None
    assert RedBalloonDetector(RedBalloonConfig(roi=False)).window((480, 640), t) is None


def test_clutter_outside_the_window_is_gated_until_the_periodic_full_search():
    every = 5
    roi = RedBalloonDetector(RedBalloonConfig(full_frame_every=every))
    full = _full()
    t = _track(roi, 400.0, 150.0, 6.0, frames=1)
    box = (60, 320, 140, 400)  # a large red box far from the balloon, larger than it
    found = []
    for i in range(1, 2 * every):
        frame = _frame([(400.0, 150.0, 6.0)], noise_seed=20 + i, boxes=[box])
        det = roi.detect(frame, t + (i - 1) * FRAME_S)
        found.append(det)
        assert full.detect(frame, 0.0).bbox_px[2] == box[2] - box[0]  # full frame: the box
    # frames 1..every-1 windowed on the balloon; frame `every` is a full search (the box
    # wins and the track moves to it), then the window follows the box
    balloon = [d.bbox_px[2] < 20 for d in found]
    assert balloon == [True] * (every - 1) + [False] * every
    assert roi.stats.windowed == 2 * every - 2 and roi.stats.fallbacks == 0


def test_clutter_inside_the_window_is_judged_as_in_the_full_frame():
    roi, full = RedBalloonDetector(), _full()
    t = _track(roi, 300.0, 200.0, 8.0)
    # a second, bigger balloon beside the tracked one, inside the window: it wins, as it does
    # in the full frame
    frame = _frame([(300.0, 200.0, 8.0), (330.0, 215.0, 12.0)], noise_seed=11)
    a = roi.detect(frame, t)
    assert a == full.detect(frame, t) and a.bbox_px[2] > 20
    assert roi.stats.windowed == 2


def test_bad_configuration_and_input_are_refused():
    with pytest.raises(ValueError, match="roi_margin_px"):
        RedBalloonDetector(RedBalloonConfig(roi_margin_px=-1.0))
    with pytest.raises(ValueError, match="full_frame_every"):
        RedBalloonDetector(RedBalloonConfig(full_frame_every=-1))
    det = RedBalloonDetector()
    with pytest.raises(ValueError, match="finite"):
        det.detect(_frame([]), float("nan"))


def _rendered_sortie(overrides, roi: bool):
    sc = with_overrides(load_scenario("static-ahead-20m"), parse_overrides(overrides))
    sim = Simulation(sc, "png", 3, "rendered", keep_records=False)
    cam = sim.camera
    cam.detector = RedBalloonDetector(dataclasses.replace(cam.detector.config, roi=roi))
    return sim, sim.run()


@pytest.mark.parametrize(
    "overrides",
    [
        [],
        [  # the detector-realism faults: false blobs, bursty drops, a range limit
            "camera.false_probability=0.1",
            "camera.false_blob_px=12",
            "camera.burst_probability=0.05",
            "camera.min_blob_px=3",
        ],
    ],
    ids=["nominal", "faults"],
)
def test_a_rendered_sortie_flies_the_same_with_and_without_the_window(overrides):
    sim_roi, res_roi = _rendered_sortie(overrides, roi=True)
    sim_full, res_full = _rendered_sortie(overrides, roi=False)
    assert res_roi == res_full
    assert sim_roi.vehicle.p == sim_full.vehicle.p
    f_roi, f_full = sim_roi.camera.faults, sim_full.camera.faults
    assert (f_roi.frames, f_roi.dropped, f_roi.false_detections, f_roi.too_small) == (
        f_full.frames,
        f_full.dropped,
        f_full.false_detections,
        f_full.too_small,
    )
    assert sim_roi.camera.detections == sim_full.camera.detections
    stats = sim_roi.camera.detector.stats
    # the window did most of the work: the frames after the pass, while the vehicle recovers
    # with the target behind it, search the whole frame
    assert stats.windowed > 0.5 * (stats.windowed + stats.full)
    if overrides:
        assert f_roi.false_detections > 0 and f_roi.dropped > 0


@pytest.mark.parametrize(
    "config",
    [
        RedBalloonConfig(),
        RedBalloonConfig(min_saturation=1, min_value=0, hue_band_deg=12),
        RedBalloonConfig(min_saturation=200, min_value=120, hue_band_deg=29),
        RedBalloonConfig(min_saturation=60, min_value=60, hue_band_deg=5),
    ],
    ids=["default", "loosest", "wide-band", "narrow-band"],
)
def test_the_red_box_bound_holds_for_every_colour(config):
    """A full-frame search masks only the box around pixels with R - max(G, B) >=
    min_redness: over all 2^24 BGR colours, every colour in the mask reaches it."""
    det = RedBalloonDetector(config)
    bound = min_redness(config)
    assert bound is not None and bound >= 1
    v = np.arange(256, dtype=np.uint8)
    b, g, r = np.meshgrid(v, v, v, indexing="ij")
    colours = np.stack([b, g, r], axis=-1).reshape(4096, 4096, 3)
    in_mask = det.mask(colours) > 0
    redness = colours[:, :, 2].astype(np.int16) - np.maximum(colours[:, :, 0], colours[:, :, 1])
    assert in_mask.any()
    assert redness[in_mask].min() >= bound
    assert min_redness(RedBalloonConfig(min_saturation=0)) is None  # greys would pass
    assert min_redness(RedBalloonConfig(hue_band_deg=30)) is None


def test_a_full_search_masks_only_the_red_box_and_finds_the_same():
    det = RedBalloonDetector(RedBalloonConfig(roi=False))
    frame = _frame([(100.0, 80.0, 6.0), (500.0, 400.0, 14.0)], noise_seed=12, boxes=[])
    assert det.red_box(frame) == pytest.approx((93, 73, 515, 415), abs=2)
    assert det.red_box(_frame([], noise_seed=13)) is None  # sky and ground: nothing red
    full_mask = det.mask(frame)
    contours = cv2.findContours(full_mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0]
    assert len(contours) == 2
    found = det.detect(frame, 0.0)
    x, y, bw, bh = cv2.boundingRect(max(contours, key=cv2.contourArea))
    assert found.bbox_px == (float(x), float(y), float(bw), float(bh))
