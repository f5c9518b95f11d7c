"""The closed loop object: gain changes, hold modes, the output guard."""

import math

import numpy as np
from numpy.testing import assert_allclose

from onboard.camera_model import CameraModel
from onboard.datatypes import Detection, GyroSample, LoopMode, VehicleParams, VehicleState
from onboard.gains import Gains
from onboard.geometry import attitude_from_yaw_pitch_roll, rotmat_to_quat
from onboard.loop import InterceptionLoop

Q_NORTH = rotmat_to_quat(attitude_from_yaw_pitch_roll(math.pi / 2))


def _state(t, vel=(0.0, 3.0, 0.0)):
    return VehicleState(t, np.array([0.0, 0.0, 10.0]), np.array(vel), Q_NORTH, np.zeros(3))


def _loop(**kw):
    return InterceptionLoop(CameraModel(), VehicleParams(), **kw)


def test_waits_and_brakes_until_first_detection():
    loop = _loop()
    tel = loop.tick(_state(0.0))
    assert tel.mode is LoopMode.WAITING and tel.dkf_lost
    assert_allclose(tel.accel_desired_enu_m_s2, [0.0, -3.0, 0.0])  # -k_brake v
    assert tel.command.body_rates_flu_rad_s[1] < 0  # nose up to brake


def test_tracks_after_detection_and_yaws_toward_target():
    loop = _loop()
    loop.tick(_state(0.0))
    loop.on_detection(Detection(0.0, (420.0, 240.0), (410, 230, 20, 20), 314.0))
    loop.on_gyro(GyroSample(0.01, np.zeros(3)))
    tel = loop.tick(_state(0.01))
    assert tel.mode is LoopMode.TRACKING
    assert loop.last_fusion[0].value == "initialised"
    # flying at 3 m/s toward a 0.3 m balloon 10 px in radius (4.6 m deep) 100 px right of
    # centre: the DKF predicts the outward translational flow f rho x_n |v| = 65.5 px/s
    e_x, e_rate_x = tel.e_est_px[0], tel.e_rate_est_px_s[0]
    assert_allclose(e_rate_x, 65.5, atol=1.5)
    assert_allclose(e_x, 100.0 + 0.01 * e_rate_x, atol=0.1)
    assert_allclose(tel.yaw_rate_cmd_rad_s, -(0.03 * e_x + 0.01 * e_rate_x), atol=1e-9)
    assert tel.los_azim_rad > 0.0


def test_gain_change_applies_at_next_tick():
    loop = _loop()
    loop.tick(_state(0.0))
    loop.on_detection(Detection(0.0, (370.0, 240.0), (360, 230, 20, 20), 314.0))
    y1 = loop.tick(_state(0.01)).yaw_rate_cmd_rad_s
    loop.set_gains(Gains(k_p=0.06))
    assert loop.gains.k_p == 0.03  # not before the tick
    y2 = loop.tick(_state(0.02)).yaw_rate_cmd_rad_s
    assert loop.gains.k_p == 0.06
    assert y2 < 1.8 * y1 < 0  # roughly doubled toward clockwise


def test_lost_target_brakes_and_holds():
    loop = _loop()
    loop.tick(_state(0.0))
    loop.on_detection(Detection(0.0, (320.0, 240.0), (310, 230, 20, 20), 314.0))
    loop.tick(_state(0.01))
    tel = None
    for k in range(2, 70):
        tel = loop.tick(_state(k * 0.01))
    assert tel.mode is LoopMode.LOST
    assert_allclose(tel.accel_desired_enu_m_s2, [0.0, -3.0, 0.0])
    assert tel.yaw_rate_cmd_rad_s == 0.0


def test_guard_never_passes_nan():
    loop = _loop()
    tel = loop.tick(_state(0.0, vel=(math.nan, 0.0, 0.0)))
    assert tel.guard_tripped and loop.guard_trips == 1
    assert np.all(np.isfinite(tel.command.body_rates_flu_rad_s))
    assert_allclose(tel.command.thrust_normalised, VehicleParams().hover_thrust_normalised)


def test_unknown_law_refused():
    import pytest

    with pytest.raises(ValueError, match="unknown guidance law 'zzz'"):
        _loop(law="zzz")


def test_detections_fused_between_ticks_fly_the_same_as_fused_in_the_tick():
    """The runtime fuses a detection on the camera thread as it arrives
    (``fuse_detections``), against the DKF's last prediction; the DKF fuses at the capture
    time either way, so the next tick's estimate and command equal those of a tick that fuses
    it, up to the last step's linearisation (the correction is propagated through the tick's
    prediction instead of carried by the buffered Jacobian), and the tick reports it."""
    a, b = _loop(), _loop()
    de = dc = 0.0
    for k in range(60):
        t = 0.005 * k
        for loop in (a, b):
            loop.on_gyro(GyroSample(t, np.array([0.0, 0.0, 0.1])))
        if k >= 20 and k % 6 == 2:
            det = Detection(t - 0.08, (330.0 + k, 250.0 - 0.5 * k), (320 + k, 240, 20, 20), 314.0)
            a.on_detection(det)
            b.on_detection(det)
            fused = b.fuse_detections()
            assert fused[0].value in ("initialised", "accepted")
        ta, tb = a.tick(_state(t)), b.tick(_state(t))
        assert a.last_fusion == b.last_fusion
        assert (ta.e_est_px is None) == (tb.e_est_px is None)
        if ta.e_est_px is not None:
            de = max(de, float(np.max(np.abs(np.subtract(tb.e_est_px, ta.e_est_px)))))
            dw = np.subtract(tb.command.body_rates_flu_rad_s, ta.command.body_rates_flu_rad_s)
            dc = max(dc, float(np.max(np.abs(dw))))
    assert tb.mode is LoopMode.TRACKING
    print(f"max |difference|: estimate {de:.4f} px, body rate command {dc:.5f} rad/s")
    assert de < 0.1
    assert dc < 0.01
