"""The IMM fed at each detection's capture time (docs/agility.md): the DKF's buffered state at
that time (DelayedKalmanFilter.state_at_capture), placed from the pose carried then
(CarriedPose.at, TargetMotionImm.update_buffered), the estimate predicted to the tick
(TargetMotionImm.predicted), and the loop that does it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.camera_model import CameraModel
from onboard.datatypes import Detection, VehicleParams, VehicleState
from onboard.estimation.dkf import DelayedKalmanFilter, DkfConfig, FusionResult
from onboard.estimation.imm import CarriedPose, TargetMotionImm, position_from_image
from onboard.geometry import attitude_from_yaw_pitch_roll, rotmat_to_quat
from onboard.loop import InterceptionLoop

CAM = CameraModel()
R_NORTH = attitude_from_yaw_pitch_roll(math.pi / 2)  # body x along +y (north)
R_MEAS = np.diag([0.05**2, 0.4**2, 0.05**2])


def _det(t: float, u: float, v: float, r_px: float = 2.4) -> Detection:
    return Detection(t, (u, v), (u - r_px, v - r_px, 2 * r_px, 2 * r_px), math.pi * r_px**2)


def test_the_dkfs_state_at_a_capture_time():
    """The first buffered prediction at or after the capture time, with the detection in it
    (the image point the replay wrote there), a copy; None without a track, before the
    buffer or at a time that is not finite."""
    dkf = DelayedKalmanFilter(CAM, DkfConfig(buffer_s=0.3))
    assert dkf.state_at_capture(0.0) is None
    dt = 0.01
    for k in range(60):
        dkf.predict(k * dt, np.zeros(3))
    assert dkf.fuse(_det(0.40, 330.0, 240.0)) is FusionResult.INITIALISED
    for k in range(60, 70):
        dkf.predict(k * dt, np.zeros(3))
    # captured between two predictions (0.452 s): the row at 0.46 s holds it
    assert dkf.fuse(_det(0.452, 334.0, 240.0)) is FusionResult.ACCEPTED
    t_row, x, P = dkf.state_at_capture(0.452)
    assert t_row == pytest.approx(0.46, abs=1e-9)
    assert dkf.e_px_at(t_row) == pytest.approx((x[0] * CAM.f_px, x[1] * CAM.f_px), abs=1e-9)
    assert x.shape == (6,) and P.shape == (6, 6) and np.all(np.diag(P) > 0.0)
    # the detection moved the point toward 334 px (14 px right of the centre's 320)
    _, x_before, _ = dkf.state_at_capture(0.44)
    assert x[0] > x_before[0]
    x[0] = 99.0
    P[:] = math.nan
    assert dkf.state_at_capture(0.452)[1][0] != 99.0  # a copy
    assert np.isfinite(dkf.state_at_capture(0.452)[2]).all()
    assert dkf.state_at_capture(0.05) is None  # older than the 0.3 s buffer
    assert dkf.state_at_capture(math.nan) is None


def test_the_carried_pose_of_a_past_step():
    pose = CarriedPose(history=3)
    v, w = np.array([1.0, 0.0, 0.0]), np.zeros(3)
    for k in range(5):
        pose.step(0.1 * k, np.array([5.0, 5.0, 5.0]), v, R_NORTH, w)
    p, R = pose.at(0.3)
    np.testing.assert_allclose(p, (5.3, 5.0, 5.0), atol=1e-12)  # anchored at 0, carried by v
    np.testing.assert_allclose(R, R_NORTH, atol=1e-12)
    assert pose.at(0.1) is None  # beyond the 3 steps held
    assert pose.at(0.35) is None  # no step then
    pose.reset()
    assert pose.at(0.4) is None


def test_update_buffered_places_the_state_from_the_pose_of_its_time():
    """The same update as placing the DKF's point by hand from the pose carried at its time;
    a time whose pose is not held changes nothing."""
    imm, twin = TargetMotionImm(), TargetMotionImm()
    v, w = np.array([0.0, 2.0, 0.0]), np.zeros(3)
    offset = (0.1, 0.0, -0.05)
    P6 = np.diag([1e-6, 1e-6, 1e-6, 1.0, 1.0, 1.0])
    for k in range(12):
        t = k / 30.0
        x = np.array((0.02, -0.01, 1.0 / (20.0 - 2.0 * t), 0.0, 0.0, 0.0))
        imm.pose.step(t, np.zeros(3), v, R_NORTH, w)
        assert imm.update_buffered(t, x, P6, np.asarray(CAM.R_BC), offset)
        p_b = v * t
        cam = p_b + R_NORTH @ np.asarray(offset)
        p, cov = position_from_image(x[0], x[1], x[2], P6[:3, :3], R_NORTH @ CAM.R_BC, cam)
        twin.update(t, p, cov, x[3:], cam)
    assert imm.estimate == twin.estimate
    before = imm.estimate
    assert not imm.update_buffered(0.5, x, P6, np.asarray(CAM.R_BC), offset)
    assert imm.estimate is before


def test_predicted_leaves_the_filter_as_it_was():
    """A target turning at 3 m/s^2: the estimate predicted 0.08 s ahead is stamped then and
    its velocity moves by about the acceleration times 0.08 s; the filter, updated on, gives
    what a twin never asked gives."""
    imm, twin = TargetMotionImm(), TargetMotionImm()
    rng = np.random.default_rng(3)
    p, vel = np.array([0.0, 20.0, 10.0]), np.array([4.0, 0.0, 0.0])
    dt = 1.0 / 30.0
    for k in range(150):
        t = k * dt
        c, s = math.cos(0.75 * dt), math.sin(0.75 * dt)
        vel = np.array([c * vel[0] - s * vel[1], s * vel[0] + c * vel[1], 0.0])
        p = p + vel * dt
        z = p + rng.multivariate_normal(np.zeros(3), R_MEAS)
        imm.update(t, z, R_MEAS, vel)
        twin.update(t, z, R_MEAS, vel)
        ahead = imm.predicted(t + 0.08)
        assert imm.estimate == twin.estimate
    assert ahead.time_s == pytest.approx(t + 0.08)
    dv = np.subtract(ahead.velocity_enu_m_s, imm.estimate.velocity_enu_m_s)
    a = np.array(imm.estimate.accel_enu_m_s2)
    np.testing.assert_allclose(dv, 0.08 * a, atol=0.05)
    assert np.linalg.norm(a) > 1.5  # the turn is seen
    assert imm.predicted(t) is imm.estimate  # not after its last update
    assert imm.predicted(t + 5.0) is imm.estimate  # beyond the gap that restarts a track


def test_the_loop_feeds_the_imm_at_capture_times_and_flies_its_estimate_at_the_tick():
    """Detections 80 ms late at 30 Hz of a target ahead: the IMM's own time is each fused
    detection's capture time (the row at or after it), not the tick's; the estimate the
    tick flies (and records) is predicted to the tick."""
    loop = InterceptionLoop(CAM, VehicleParams(), law="apn")
    q = rotmat_to_quat(R_NORTH)
    imm_times, flown_times = [], []
    for k in range(120):
        t = k / 100.0
        if k >= 10 and k % 3 == 0:
            loop.on_detection(_det(t - 0.08, 330.0 + 0.05 * k, 240.0))
        fusing = bool(loop._detections)
        loop.tick(VehicleState(t, np.array([0.0, 0.0, 10.0]), np.zeros(3), q, np.zeros(3)))
        motion = loop._motion_now
        if fusing and motion is not None and loop.motion.estimate is not None:
            imm_times.append(t - loop.motion.estimate.time_s)
            flown_times.append(t - motion.time_s)
    assert len(imm_times) > 20
    np.testing.assert_allclose(imm_times[2:], 0.08, atol=0.0101)
    np.testing.assert_allclose(flown_times, 0.0, atol=1e-9)


def test_a_loop_without_the_imm_keeps_no_capture_times():
    """PNG, the default, flies without the IMM when nothing records it (onboard, campaigns):
    the capture times it would be fed are not kept (they would pile up for as long as the
    vehicle flies)."""
    from groundstation.scenario import load_scenario
    from groundstation.sim.simulation import Simulation

    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 1, keep_records=False)
    assert sim.run().outcome == "HIT" and sim.loop.motion is None
    assert sim.loop._fused_capture_s == []  # main: one entry per fused detection


def _hover_with_a_velocity_correction(loop: InterceptionLoop) -> tuple[float, float, float]:
    """A vehicle at rest 20 m south of a hovering target, detections at 30 Hz 80 ms late; at
    1 s its velocity estimate jumps to 0.5 m/s east (an estimator's correction: the vehicle
    does not move) and stays. Returns (the carried frame's east shift over 1-1.5 s, the
    loop's own velocity east integrated over it (m), the largest east acceleration (m/s^2)
    the IMM estimated after the jump)."""
    q = rotmat_to_quat(R_NORTH)
    integrated = a_max = 0.0
    p0 = None
    for k in range(150):
        t = k / 100.0
        if k >= 10 and k % 3 == 0:
            loop.on_detection(_det(t - 0.08, 320.0, 240.0))
        v = np.array([0.5 if t >= 1.0 else 0.0, 0.0, 0.0])
        loop.tick(VehicleState(t, np.array([0.0, 0.0, 10.0]), v, q, np.zeros(3)))
        if k == 100:
            p0 = loop.motion.pose.position_enu_m.copy()
        elif k > 100:
            integrated += 0.01 * loop.own_velocity.velocity_enu_m_s[0]
            a_max = max(a_max, abs(loop.motion.estimate.accel_enu_m_s2[0]))
    shift = float(loop.motion.pose.position_enu_m[0] - p0[0])
    return shift, integrated, a_max


def test_the_imms_frame_is_carried_by_the_loops_own_velocity():
    """The frame the IMM places the target in moves with the own velocity the DKF's relative
    motion is predicted with (lag-compensated, complementary-filtered: the thrust model for the
    fast part), so a jump of the velocity estimate is not a jump of the target: 0.05 m and
    0.009 m/s^2 where the raw estimate carried it 0.25 m and the IMM saw 0.08 m/s^2."""
    shift, integrated, a_max = _hover_with_a_velocity_correction(
        InterceptionLoop(CAM, VehicleParams(), law="apn")
    )
    assert shift == pytest.approx(integrated, abs=1e-9)
    assert abs(shift) < 0.1  # the raw estimate integrated: 0.245 m
    assert a_max < 0.03  # carried by the raw estimate: 0.079 m/s^2
