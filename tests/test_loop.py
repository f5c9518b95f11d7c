"""The closed loop object: gain changes, hold modes, the output guard."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from onboard.camera_model import CameraModel
from onboard.control.reacquire import search_yaw_rate
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


def test_lost_target_brakes_and_holds_without_coast_or_search():
    # t_coast = t_reacq = t_search = 0: the failsafe as soon as the track goes stale; without
    # the velocity-latency prediction (tested in test_midcourse) and the own-velocity filter
    # (test_own_velocity) it brakes on v itself
    loop = _loop(gains=Gains(t_coast=0.0, t_reacq=0.0, t_search=0.0, t_vel_lag=0.0, tau_vel=0.0))
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


def _stale_track_modes(gains):
    """A hovering loop handed a 0.3 m balloon 20 m ahead, 10 px right of centre, at 30 Hz
    until 0.38 s; the mode and command at every tick after that until 7 s."""
    loop = _loop(gains=gains)
    hover = (0.0, 0.0, 0.0)
    loop.tick(_state(0.0, hover))
    for k in range(1, 40):
        t = k / 100
        if k % 3 == 0:  # 2.4 px radius: 20 m
            loop.on_detection(Detection(t - 0.01, (330.0, 240.0), (327.6, 237.6, 4.8, 4.8), 18.1))
        mode = loop.tick(_state(t, hover)).mode
    assert mode is LoopMode.TRACKING
    return [(k / 100, loop.tick(_state(k / 100, hover))) for k in range(40, 700)]


def test_stale_track_coasts_reacquires_searches_then_fails_safe():
    ticks = _stale_track_modes(Gains(t_search=2.0))
    first = {}
    for t, tel in ticks:
        first.setdefault(tel.mode, (t, tel))
    # the DKF goes stale 0.5 s after the last detection (0.38 s): coast on its prediction for
    # t_coast = 1 s (its 1 sigma grows ~20 px/s here, under coast_std = 40 px), then
    # re-acquire for t_reacq = 3 s, search for t_search = 2 s, then brake and hold
    assert_allclose(first[LoopMode.COAST][0], 0.89, atol=0.011)
    assert_allclose(first[LoopMode.REACQUIRE][0], 1.89, atol=0.011)
    assert_allclose(first[LoopMode.SEARCH][0], 4.89, atol=0.011)
    assert_allclose(first[LoopMode.LOST][0], 6.89, atol=0.011)
    # coasting: the guidance law on the prediction (hover start along the LOS at k_a) and
    # the FOV-holding yaw toward it (right of centre: clockwise)
    tel = first[LoopMode.COAST][1]
    assert_allclose(np.linalg.norm(tel.accel_desired_enu_m_s2), 2.0, atol=1e-6)
    assert tel.yaw_rate_cmd_rad_s < 0.0
    # re-acquiring: toward the predicted LOS at v_reacq = 1 m/s (k_brake (v_d - v)), yawing
    tel = first[LoopMode.REACQUIRE][1]
    assert_allclose(np.linalg.norm(tel.accel_desired_enu_m_s2), 1.0, atol=1e-6)
    assert tel.accel_desired_enu_m_s2[1] > 0.99  # north, the camera's heading
    assert tel.yaw_rate_cmd_rad_s < 0.0
    # searching at hover: a yaw scan at w_search, clockwise (the side it was last seen)
    tel = first[LoopMode.SEARCH][1]
    assert tel.yaw_rate_cmd_rad_s == -0.6
    assert_allclose(tel.accel_desired_enu_m_s2, 0.0, atol=1e-12)
    tel = first[LoopMode.LOST][1]
    assert tel.yaw_rate_cmd_rad_s == 0.0


def test_coast_ends_early_when_the_prediction_is_uncertain():
    ticks = _stale_track_modes(Gains(coast_std=20.0))
    coast = [t for t, tel in ticks if tel.mode is LoopMode.COAST]
    # 1 sigma passes 20 px about 0.8 s after the last detection, not 1.5 s
    assert coast and 0.1 < coast[-1] - coast[0] < 0.6


def test_search_before_the_first_detection_flies_the_launch_course():
    loop = _loop()
    modes = [loop.tick(_state(k / 100)).mode for k in range(0, 60)]
    assert modes[0] is LoopMode.WAITING and modes[49] is LoopMode.WAITING
    assert modes[50] is LoopMode.SEARCH  # t_wait = 0.5 s
    tel = loop.tick(_state(0.6, (0.0, 1.0, 0.0)))
    # the cue is the launch heading (the camera looked north at the first tick): v_search =
    # 8 m/s along it
    assert_allclose(tel.accel_desired_enu_m_s2, [0.0, 5.0, 0.0], atol=1e-9)  # k_brake 7, a_max
    # the camera weaves about it, the amplitude growing over two periods (6 s): 0.1 s into
    # the search psi_d = 40 deg (0.1 / 6) sin(2 pi 0.1 / 3) = 0.139 deg left of north,
    # psi_d' = 0.048 rad/s, plus k_R = 8 times the heading error
    w, amp, r = 2.0 * math.pi / 3.0, math.radians(40.0), 0.1 / 6.0
    psi_dot = amp * (r * w * math.cos(0.1 * w) + math.sin(0.1 * w) / 6.0)
    err = amp * r * math.sin(0.1 * w)
    assert tel.yaw_rate_cmd_rad_s == pytest.approx(psi_dot + 8.0 * err, rel=1e-9)
    # once grown, the full weave: 40 deg to each side, 1.46 rad/s at the crossing
    t = 7.5  # 2.5 periods: psi_d = 0, crossing the course to the right
    north = np.array([0.0, 1.0, 0.0])
    rate = search_yaw_rate(north, north, 1.0, Gains(), search_time_s=t)
    assert rate == pytest.approx(amp * w * math.cos(w * t), rel=1e-9)
    assert rate == pytest.approx(-1.462, abs=1e-3)
    g = Gains(weave_deg=0.0)
    loop = _loop(gains=g)
    for k in range(0, 60):
        loop.tick(_state(k / 100))
    assert abs(loop.tick(_state(0.6, (0.0, 1.0, 0.0))).yaw_rate_cmd_rad_s) < 1e-9  # no weave


@pytest.mark.parametrize("on_arrival", [False, True], ids=["fused-in-tick", "fused-on-arrival"])
def test_a_far_detection_needs_confirmation_after_a_loss(on_arrival):
    """The screen holds on both fusion paths: in the tick (the simulator) and on arrival
    (``fuse_detections``, the vehicle's camera thread)."""
    loop = _loop(gains=Gains(t_search=2.0))
    hover = (0.0, 0.0, 0.0)

    def hand(det: Detection) -> None:
        loop.on_detection(det)
        if on_arrival:
            loop.fuse_detections()

    loop.tick(_state(0.0, hover))
    for k in range(1, 40):
        if k % 3 == 0:
            hand(Detection(k / 100 - 0.01, (330.0, 240.0), (327.6, 237.6, 4.8, 4.8), 18.1))
        loop.tick(_state(k / 100, hover))
    for k in range(40, 120):
        tel = loop.tick(_state(k / 100, hover))
    assert tel.mode is LoopMode.COAST
    # one false blob far from the prediction (200 px left): held, not fused
    hand(Detection(1.18, (130.0, 200.0), (127.5, 197.5, 5, 5), 19.6))
    assert loop.tick(_state(1.2, hover)).mode is LoopMode.COAST
    assert loop.last_fusion == [] and not loop.dkf.estimate().e_px[0] < 0
    # the target where the prediction says: fused at once (a track stale this long restarts
    # the DKF from it), tracking again
    hand(Detection(1.2, (331.0, 240.0), (328.6, 237.6, 4.8, 4.8), 18.1))
    tel = loop.tick(_state(1.21, hover))
    assert [r.value for r in loop.last_fusion] == ["initialised"]
    assert tel.mode is LoopMode.TRACKING
    assert_allclose(tel.e_est_px[0], 11.0, atol=1.0)


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


def _yawing_pass(
    stale: range,
    jump_rad: float,
    monkeypatch,
    rate: float = 1.0,
    stamped: bool = False,
    heading_walk_rad: float = 0.0,
) -> list:
    """Fly PNG at 3 m/s north toward a still target 20 m ahead while the vehicle yaws at
    ``rate`` (rad/s; the gyro says so every tick); on the ticks in ``stale`` the attitude
    handed to the loop is frozen at the one before them (a starved attitude stream), then
    fresh again; ``stamped``: the state says when its attitude is of (``attitude_time_s``, as
    the runtime's does); ``heading_walk_rad``: the handed attitude's heading wanders by this
    much per tick (a random walk, seeded), as a magnetometer-fused heading does. The
    commanded accelerations (m/s^2 ENU), tick by tick, then the loop's counts of jumped and
    stale attitudes."""
    import onboard.gyro_turn as gyro_turn_module

    monkeypatch.setattr(gyro_turn_module, "ATTITUDE_JUMP_RAD", jump_rad)
    cam = CameraModel()
    loop = _loop()
    target = np.array([0.0, 20.0, 10.0])
    out, handed, handed_t = [], None, 0.0
    walk = np.cumsum(np.random.default_rng(7).normal(0.0, heading_walk_rad, 60))
    for k in range(60):
        t = 0.01 * k
        p = np.array([0.0, 3.0 * t, 10.0])
        R_WB = attitude_from_yaw_pitch_roll(math.pi / 2 + 0.3 - rate * t)
        if k % 3 == 0:  # the camera sees the true attitude
            u, v = cam.project((R_WB @ cam.R_BC).T @ (target - p))
            loop.on_detection(Detection(t, (u, v), (u - 10, v - 10, 20, 20), 314.0))
        loop.on_gyro(GyroSample(t, np.array([0.0, 0.0, -rate])))
        if k not in stale:  # else the last one handed again
            c, s_ = math.cos(walk[k]), math.sin(walk[k])
            R_err = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
            handed, handed_t = rotmat_to_quat(R_err @ R_WB), t
        vel, w = np.array([0.0, 3.0, 0.0]), np.array([0.0, 0.0, -rate])
        tel = loop.tick(VehicleState(t, p, vel, handed, w, handed_t if stamped else None))
        assert tel.mode is LoopMode.TRACKING or k == 0
        out.append(np.array(tel.accel_desired_enu_m_s2))
    out.append((loop.gyro_turn.attitude_jumps, loop.gyro_turn.stale_attitude_ticks))
    return out


def _deviation(run: list, fresh: list) -> float:
    """The largest |a_d - a_d flown with fresh attitudes| over the pass (m/s^2)."""
    return max(float(np.linalg.norm(a - b)) for a, b in zip(run, fresh, strict=True))


def test_a_stale_attitude_replaced_by_a_fresh_one_does_not_jerk_the_command(monkeypatch):
    # 0.15 s without a fresh attitude while yawing at 1 rad/s: each tick's attitude is 10 mrad
    # off what the gyro turned, and the fresh one 150 mrad from the last. The LOS change of
    # two ticks' attitudes would carry those and PNG turn K times them in one command (the
    # command sat at a_max and flipped sign when the fresh attitude came); through this
    # tick's attitude and the gyro it is the target's
    *fresh, counts_fresh = _yawing_pass(range(0), 0.005, monkeypatch)
    *guarded, counts = _yawing_pass(range(30, 45), 0.005, monkeypatch)
    assert counts_fresh == (0, 0) and counts == (16, 0)  # 15 stale ticks (10 mrad), the fresh
    dev = _deviation(guarded, fresh)
    print(f"max |a_d - fresh|: {dev:.3f} m/s^2")
    # what is left is the stale attitude's error in the LOS's direction (up to 150 mrad of it
    # here, through the speed ramp): 0.39 m/s^2
    assert dev < 0.5
    assert float(np.dot(guarded[45], guarded[44])) > 0.0


def test_a_wandering_heading_estimate_does_not_steer_the_command(monkeypatch):
    # the heading estimate wanders by 4 mrad (0.25 deg) per tick, as a magnetometer-fused
    # heading with a 2 s correlation time and 2.5 deg of error does at 100 Hz: PNG on the
    # difference of two attitude estimates would turn K times 0.4 rad/s of false LOS rate
    *fresh, _ = _yawing_pass(range(0), 0.005, monkeypatch, rate=0.3)
    *walked, _ = _yawing_pass(range(0), math.inf, monkeypatch, rate=0.3, heading_walk_rad=0.004)
    dev = _deviation(walked, fresh)
    print(f"max |a_d - fresh| with a wandering heading: {dev:.3f} m/s^2")
    assert dev < 0.3  # the heading's error itself (tens of mrad) through the speed ramp


def test_a_stale_attitude_turning_slowly_is_known_by_its_age(monkeypatch):
    # at 0.3 rad/s a frozen attitude falls 3 mrad behind a tick, under the jump threshold:
    # only its age (the runtime stamps it) tells it is stale; the fresh attitude's arrival is
    # a jump. Either way the LOS change is the gyro's
    *fresh, _ = _yawing_pass(range(0), 0.005, monkeypatch, rate=0.3, stamped=True)
    *aged, counts = _yawing_pass(range(30, 45), 0.005, monkeypatch, rate=0.3, stamped=True)
    *unaged, counts_unaged = _yawing_pass(range(30, 45), 0.005, monkeypatch, rate=0.3)
    assert counts == (1, 15) and counts_unaged == (1, 0)
    dev, dev_unaged = _deviation(aged, fresh), _deviation(unaged, fresh)
    print(f"max |a_d - fresh|: by age {dev:.3f}, without {dev_unaged:.3f} m/s^2")
    assert dev < 0.3 and dev_unaged < 0.3


def test_the_attitude_is_not_judged_after_a_stall_or_with_non_finite_rates():
    loop = _loop()
    loop.tick(_state(0.0))
    R = attitude_from_yaw_pitch_roll(math.pi / 2 + 0.02)  # 20 mrad from the last tick's
    dt = loop.nominal_dt_s
    now, stale = _state(dt), _state(dt)
    stale.attitude_time_s = 0.0  # not carried to the tick
    turn = loop.gyro_turn.through_gyro
    assert turn(now, R, np.zeros(3), dt)  # a jump (counted)
    assert turn(stale, loop.gyro_turn.prev_R_WB, np.zeros(3), dt)  # stale (counted)
    # the gyro saw the turn: no jump, and still through the gyro
    assert turn(now, R, np.array([0.0, 0.0, 0.02 / dt]), dt)
    # a late tick (a stall): the mean rate times the interval is no better than two attitudes
    assert not turn(now, R, np.zeros(3), 3.0 * dt)
    assert not turn(stale, R, np.zeros(3), 3.0 * dt)
    # no rates to turn back by (propagate_rotation ignores them): the attitudes stand
    for bad in (math.inf, math.nan):
        assert not turn(now, R, np.array([bad, 0.0, 0.0]), dt)
        assert not turn(stale, R, np.array([bad, 0.0, 0.0]), dt)
    assert (loop.gyro_turn.attitude_jumps, loop.gyro_turn.stale_attitude_ticks) == (1, 1)
