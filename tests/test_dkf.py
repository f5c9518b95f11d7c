"""Delayed Kalman filter (DESIGN.md §4)."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from onboard.camera_model import CameraModel
from onboard.datatypes import Detection
from onboard.estimation.dkf import DelayedKalmanFilter, DkfConfig, FusionResult
from onboard.geometry import attitude_from_yaw_pitch_roll, hat

CAM = CameraModel()


def _det(t, u, v):
    return Detection(t, (u, v), (u - 2, v - 2, 4, 4), 16.0)


def _approach(delay_s=0.08, rate_hz=30, dt=0.005, duration_s=4.0, seed=1):
    """A manoeuvring approach: vehicle closing at 5 m/s while its attitude swings (rates up to
    ~1 rad/s on every axis); 1 px detection noise, detections `delay_s` late."""
    rng = np.random.default_rng(seed)
    R = attitude_from_yaw_pitch_roll(math.pi / 2)
    p, v = np.array([0.0, 0.0, 10.0]), np.array([0.0, 5.0, 0.0])
    target = np.array([1.0, 25.0, 11.0])
    every = round(1 / rate_hz / dt)
    for k in range(int(duration_s / dt)):
        t = k * dt
        w = np.array(
            [
                0.8 * math.sin(2 * math.pi * 0.7 * t),
                0.6 * math.sin(2 * math.pi * 0.5 * t + 1),
                0.7 * math.cos(2 * math.pi * 0.4 * t),
            ]
        )
        if k:
            th = np.linalg.norm(w) * dt
            K = hat(w / np.linalg.norm(w))
            R = R @ (np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K)
            p = p + v * dt
        uv = CAM.project((R @ CAM.R_BC).T @ (target - p))
        det = None
        if k % every == 0:
            det = _det(t, uv[0] + rng.normal(), uv[1] + rng.normal())
        yield t, w, uv, det, t + delay_s


def test_dkf_beats_latest_delayed_detection_by_3x():
    dkf = DelayedKalmanFilter(CAM)
    pending, err_dkf, err_raw, latest = [], [], [], None
    for t, w, uv, det, arrival in _approach():
        dkf.predict(t, w)
        if det is not None:
            pending.append((arrival, det))
        for item in [x for x in pending if x[0] <= t + 1e-9]:
            pending.remove(item)
            assert dkf.fuse(item[1]) in (FusionResult.ACCEPTED, FusionResult.INITIALISED)
            latest = item[1]
        est = dkf.estimate()
        if est is not None and t > 0.5:
            truth = CAM.error_px(*uv)
            err_dkf.append(np.subtract(est.e_px, truth))
            err_raw.append(np.subtract(CAM.error_px(*latest.center_px), truth))

    def rms(e):
        return math.sqrt(np.mean(np.sum(np.square(e), axis=1)))

    ratio = rms(err_raw) / rms(err_dkf)
    print(f"RMS latest detection {rms(err_raw):.2f} px, DKF {rms(err_dkf):.2f} px, x{ratio:.1f}")
    assert rms(err_raw) > 10.0  # the delay really hurts in this manoeuvre
    assert ratio >= 3.0


def _filter_with(dets, order):
    dkf = DelayedKalmanFilter(CAM)
    t = 0.0
    for k in range(121):
        t = k * 0.005
        dkf.predict(t, np.array([0.0, 0.0, 0.3]))
    results = [dkf.fuse(dets[i]) for i in order]
    return dkf, results


def test_out_of_order_detections_fuse_in_capture_order():
    dets = [_det(0.2 + 0.033 * i, 330 + 2 * i, 250 - i) for i in range(8)]
    in_order, r1 = _filter_with(dets, range(8))
    shuffled, r2 = _filter_with(dets, [0, 1, 4, 2, 3, 7, 5, 6])
    assert r1[0] == r2[0] == FusionResult.INITIALISED
    assert all(r == FusionResult.ACCEPTED for r in r1[1:] + r2[1:])
    a, b = in_order.estimate(), shuffled.estimate()
    assert_allclose(a.e_px, b.e_px, atol=1e-9)
    assert_allclose(a.e_rate_px_s, b.e_rate_px_s, atol=1e-9)


def test_duplicate_detection_is_rejected_and_changes_nothing():
    dets = [_det(0.2 + 0.033 * i, 330 + 2 * i, 250) for i in range(4)]
    dkf, _ = _filter_with(dets, range(4))
    before = dkf.estimate()
    assert dkf.fuse(dets[2]) == FusionResult.DUPLICATE
    assert dkf.estimate() == before


def test_detection_older_than_buffer_is_rejected_cleanly():
    dkf = DelayedKalmanFilter(CAM, DkfConfig(buffer_s=0.3))
    for k in range(200):
        dkf.predict(k * 0.005, np.zeros(3))
    assert dkf.fuse(_det(0.9, 320, 240)) == FusionResult.INITIALISED
    before = dkf.estimate()
    assert dkf.fuse(_det(0.5, 330, 240)) == FusionResult.TOO_OLD  # 0.495 s late > 0.3 s
    assert dkf.fuse(_det(1.5, 330, 240)) == FusionResult.FUTURE
    assert dkf.fuse(_det(0.95, math.nan, 240)) == FusionResult.GATED
    assert dkf.estimate() == before
    assert dkf.counts[FusionResult.TOO_OLD] == 1


def test_outlier_is_gated():
    dets = [_det(0.2 + 0.033 * i, 330, 250) for i in range(6)]
    dkf, _ = _filter_with(dets, range(6))
    before = dkf.estimate()
    assert dkf.fuse(_det(0.59, 600, 20)) == FusionResult.GATED
    assert_allclose(dkf.estimate().e_px, before.e_px)


def test_lost_after_timeout_and_reacquired():
    dkf = DelayedKalmanFilter(CAM)
    assert dkf.estimate() is None and dkf.lost(0.0)
    dkf.predict(0.0, np.zeros(3))
    dkf.predict(0.1, np.zeros(3))
    assert dkf.fuse(_det(0.05, 320, 240)) == FusionResult.INITIALISED
    assert not dkf.estimate().lost
    for k in range(3, 130):
        dkf.predict(k * 0.005 + 0.1, np.zeros(3))
    est = dkf.estimate()
    assert est.lost and est.time_since_detection_s > 0.5
    dkf.predict(0.8, np.zeros(3))
    assert dkf.fuse(_det(0.75, 300, 200)) == FusionResult.INITIALISED
    assert not dkf.lost()


def test_gyro_flow_moves_estimate_between_detections():
    """Yawing left (positive about body z) sweeps a centred point to the right (e_x grows)
    at f * w px/s; the DKF predicts it from the gyro alone."""
    dkf = DelayedKalmanFilter(CAM)
    dkf.predict(0.0, np.zeros(3))
    dkf.fuse(_det(0.0, 320, 240))
    for k in range(1, 11):
        dkf.predict(k * 0.005, np.array([0.0, 0.0, 0.5]))
    assert_allclose(dkf.estimate().e_px[0], CAM.f_px * 0.5 * 0.05, rtol=1e-3)


@pytest.mark.parametrize("bad", [{"meas_noise_px": 0.0}, {"lost_timeout_s": math.nan}])
def test_config_validated(bad):
    with pytest.raises(ValueError, match="DkfConfig"):
        DkfConfig(**bad)
