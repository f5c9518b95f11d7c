"""The IMM over the target's world motion (onboard/estimation/imm.py): the models switch on a
simulated turn, a straight flyer reports almost no acceleration, bad input changes nothing."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from onboard.control.apn import manoeuvre_accel_m_s2
from onboard.estimation.imm import (
    MODELS,
    CarriedPose,
    ImmConfig,
    TargetMotionImm,
    pose_covariance_m2,
    position_from_image,
)

DT = 1.0 / 30.0  # the camera's rate
# the DKF's position error: 5 cm across the line of sight (+y), 40 cm along it
R_MEAS = np.diag([0.05**2, 0.4**2, 0.05**2])


def _fly(turn_at_s: float | None, lateral_m_s2: float, seed: int, seconds: float = 10.0):
    """A target at 4 m/s along +x, 20 m ahead of an observer at the origin, turning left at
    ``lateral_m_s2`` from ``turn_at_s``; rows (t, probabilities (3), a estimated (3), a true
    (3))."""
    rng = np.random.default_rng(seed)
    imm = TargetMotionImm()
    p, v = np.array([0.0, 20.0, 10.0]), np.array([4.0, 0.0, 0.0])
    rows = []
    for k in range(round(seconds / DT)):
        t = k * DT
        turning = turn_at_s is not None and t > turn_at_s
        if turning:
            w = lateral_m_s2 / 4.0 * DT
            v = np.array(
                [
                    math.cos(w) * v[0] - math.sin(w) * v[1],
                    math.sin(w) * v[0] + math.cos(w) * v[1],
                    0.0,
                ]
            )
        p = p + v * DT
        e = imm.update(t, p + rng.multivariate_normal(np.zeros(3), R_MEAS), R_MEAS, v)
        a_true = lateral_m_s2 / 4.0 * np.array([-v[1], v[0], 0.0]) if turning else np.zeros(3)
        rows.append((t, *e.probabilities, *e.accel_enu_m_s2, *a_true))
    return np.array(rows)


def test_the_models_switch_on_a_turn():
    for seed in (1, 2, 3):
        rows = _fly(turn_at_s=4.0, lateral_m_s2=3.0, seed=seed)
        straight = rows[(rows[:, 0] > 1.0) & (rows[:, 0] <= 4.0)]
        turning = rows[rows[:, 0] > 5.0]
        mu_straight, mu_turn = straight[:, 1:4].mean(axis=0), turning[:, 1:4].mean(axis=0)
        assert mu_straight[MODELS.index("cv")] > 0.6, mu_straight
        assert mu_turn[MODELS.index("cv")] < 0.25, mu_turn
        assert mu_turn[MODELS.index("ct")] > 0.3, mu_turn
        # the acceleration across the line of sight (x): within 0.9 m/s^2 RMS of the true 3
        err = turning[:, 4] - turning[:, 7]
        assert math.sqrt(float(np.mean(err**2))) < 0.9


def test_a_fast_turn_is_followed_in_phase():
    """5 m/s^2 at 4 m/s turns the acceleration at 1.25 rad/s: CT carries that turn over each
    step (a CT at CA's turn rate, a phase behind, gave 0.57-0.58 of it, 3.2 m/s^2 RMS off)."""
    for seed in (1, 2, 3):
        rows = _fly(turn_at_s=2.0, lateral_m_s2=5.0, seed=seed, seconds=6.0)
        late = rows[rows[:, 0] > 3.5]
        a_est, a_true = late[:, 4:7], late[:, 7:10]
        along = float(np.mean(np.sum(a_est * a_true, axis=1))) / 25.0
        rms = math.sqrt(float(np.mean(np.sum((a_est - a_true) ** 2, axis=1))))
        assert along > 0.7, along  # 0.76-0.77
        assert rms < 2.6, rms  # 2.0-2.2 m/s^2


def test_a_straight_flyer_gives_almost_no_acceleration():
    rows = _fly(turn_at_s=None, lateral_m_s2=0.0, seed=4)
    settled = rows[rows[:, 0] > 1.0]
    across = np.hypot(settled[:, 4], settled[:, 6])  # x and z: across the line of sight
    assert math.sqrt(float(np.mean(across**2))) < 0.05
    assert settled[:, 1].mean() > 0.6


def _turn_followed(
    lateral_m_s2: float, seed: int, r_meas: np.ndarray = R_MEAS, config: ImmConfig | None = None
) -> tuple[float, float]:
    """A target at 5 m/s, 20 m ahead, turning at ``lateral_m_s2`` from t = 2 s, measured with
    covariance ``r_meas`` and placed with the vehicle's pose uncertainty (camera at the
    origin): the share of the true acceleration across the line of sight that the augmented
    law flies (manoeuvre_accel_m_s2) from 0.5 to 2.5 s into the turn, and the time (s) it
    takes to reach half the truth."""
    rng = np.random.default_rng(seed)
    imm = TargetMotionImm(config)
    p, v = np.array([0.0, 20.0, 10.0]), np.array([5.0, 0.0, 0.0])
    est, true, t_half = [], [], math.nan
    for k in range(round(6.0 / DT)):
        t = k * DT
        turning = t > 2.0
        if turning:
            c, s = math.cos(lateral_m_s2 / 5.0 * DT), math.sin(lateral_m_s2 / 5.0 * DT)
            v = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], 0.0])
        p = p + v * DT
        z = p + rng.multivariate_normal(np.zeros(3), r_meas)
        flown = manoeuvre_accel_m_s2(imm.update(t, z, r_meas, v, np.zeros(3)), 1.0, 2.0)
        a_x = -lateral_m_s2 / 5.0 * v[1] if turning else 0.0  # x: across the line of sight
        if turning and math.isnan(t_half) and flown[0] * math.copysign(1.0, a_x) > 0.5 * abs(a_x):
            t_half = t - 2.0
        if 2.5 < t < 4.5:
            est.append(flown[0])
            true.append(a_x)
    est_a, true_a = np.array(est), np.array(true)
    return float(est_a @ true_a / (true_a @ true_a)), t_half


def test_the_lag_of_a_turn_placed_through_the_pose_uncertainty():
    """With the pose's uncertainty in the measurement (0.2 m, 0.6 deg at 20 m: 0.29 m across
    the line of sight, where a 3 m/s^2 turn moves the target 0.38 m off its line in 0.5 s)
    the law flies 0.52-0.59 of a 3 or 5 m/s^2 turn from 0.5 to 2.5 s into it, and half of it
    only 1.4-1.6 s in: the lag docs/agility.md sets against the sortie's few seconds."""
    for lateral in (3.0, 5.0):
        for seed in (1, 2, 3):
            share, t_half = _turn_followed(lateral, seed)
            assert 0.45 < share < 0.65, (lateral, seed, share)
            assert 1.3 < t_half < 1.8, (lateral, seed, t_half)


def test_at_capture_time_the_pose_term_holds_the_lag():
    """The loop feeds the DKF's state at each detection's capture time, 0.02-0.10 m across the
    line of sight in flight (the head, carried over the camera's delay, 0.13-0.33 m): measured
    so (0.07 m across, 2 m along), a 3 or 5 m/s^2 turn is flown to 0.29-0.37 of it, half of it
    1.7-2.2 s in; at the head's 0.25 m, 0.25-0.34 of it. Without the pose's term half of it
    comes 1.4-1.9 s in and 0.43-0.51 of it is flown: the pose's uncertainty holds the IMM
    back."""
    no_pose = ImmConfig(pose_position_sigma_m=0.0, pose_attitude_sigma_deg=0.0)
    at_capture = np.diag([0.07**2, 2.0**2, 0.07**2])
    head = np.diag([0.25**2, 2.0**2, 0.25**2])
    for lateral in (3.0, 5.0):
        for seed in (1, 2):
            share, t_half = _turn_followed(lateral, seed, at_capture)
            assert 1.5 < t_half < 2.3 and 0.25 < share < 0.45, (lateral, seed, share, t_half)
            assert _turn_followed(lateral, seed, head)[0] < share - 0.02
            share_np, t_half_np = _turn_followed(lateral, seed, at_capture, no_pose)
            assert t_half_np < t_half - 0.15 and share_np > share + 0.1, (share_np, t_half_np)


def test_the_carried_frames_velocity_error_as_process_noise():
    """The coloured-noise form (ImmConfig.frame_velocity_sigma_m_s, off by default): the pose
    term out of the measurement, the carried frame's velocity error (0.15 m/s over 1 s) in
    every model's process noise. A hovering target seen through the wandering pose shows
    under 0.1 m/s^2 (0.04-0.07; without the process noise 0.14-0.25), and a turn measured to
    5 cm is followed in 1.0-1.3 s to half (1.6-1.9 s with the pose term)."""
    coloured = ImmConfig(
        pose_position_sigma_m=0.0, pose_attitude_sigma_deg=0.0, frame_velocity_sigma_m_s=0.15
    )
    white = dataclasses.replace(coloured, frame_velocity_sigma_m_s=0.0)
    for seed in (7, 8):
        assert _hover_with_pose_errors(True, seed, coloured) < 0.1
    assert max(_hover_with_pose_errors(True, s, white) for s in (7, 8)) > 0.2
    for lateral in (3.0, 5.0):
        share, t_half = _turn_followed(lateral, 1, config=coloured)
        assert 0.9 < t_half < 1.35 and share > 0.6, (lateral, share, t_half)
    for bad in ({"frame_velocity_sigma_m_s": -0.1}, {"frame_velocity_time_s": 0.0}):
        with pytest.raises(ValueError):
            ImmConfig(**bad)


def test_bad_input_changes_nothing_and_a_gap_restarts():
    imm = TargetMotionImm()
    first = imm.update(0.0, np.array([0.0, 20.0, 10.0]), R_MEAS, np.array([4.0, 0.0, 0.0]))
    assert first is not None and first.probabilities == (0.8, 0.1, 0.1)
    for bad in (np.array([math.nan, 20.0, 10.0]), np.array([1.0, 2.0])):
        assert imm.update(0.1, bad, R_MEAS) is first
    assert imm.update(0.1, np.array([0.4, 20.0, 10.0]), np.full((3, 3), math.inf)) is first
    assert imm.update(0.0, np.array([0.4, 20.0, 10.0]), R_MEAS) is first  # time not advancing
    no_depth = np.diag([0.01, 1e6, 0.01])  # a target at an unknown range: 1 km along the LOS
    assert imm.update(0.1, np.array([0.4, 20.0, 10.0]), no_depth) is first
    later = imm.update(5.0, np.array([9.0, 20.0, 10.0]), R_MEAS)  # a 5 s gap: a new track
    assert later.probabilities == (0.8, 0.1, 0.1) and later.time_s == 5.0


def test_position_from_image_and_its_covariance():
    R_WC = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # looking along +y
    cam = np.array([1.0, 2.0, 3.0])
    xn, yn, rho = 0.1, -0.05, 1.0 / 20.0
    P3 = np.diag([1e-6, 1e-6, (0.1 * rho) ** 2])
    p, cov = position_from_image(xn, yn, rho, P3, R_WC, cam)
    np.testing.assert_allclose(p, cam + R_WC @ (np.array([xn, yn, 1.0]) * 20.0), rtol=1e-12)
    # 10 % inverse depth: about 2 m along the ray; 1e-3 in the image: 2 cm (20 m x 1e-3) across
    ray = R_WC @ np.array([xn, yn, 1.0])
    along = ray / np.linalg.norm(ray)
    across = R_WC @ np.array([1.0, 0.0, -xn])
    across /= np.linalg.norm(across)
    assert abs(float(across @ along)) < 1e-12
    sigma_along = math.sqrt(float(along @ cov @ along))
    np.testing.assert_allclose(sigma_along, 2.0 * np.linalg.norm(ray), rtol=0.01)
    np.testing.assert_allclose(math.sqrt(float(across @ cov @ across)), 0.02, rtol=0.01)


def test_the_pose_uncertainty_is_added_across_the_line_of_sight():
    cfg = ImmConfig(pose_position_sigma_m=0.3, pose_attitude_sigma_deg=1.5)
    cov = pose_covariance_m2(np.array((0.0, 20.0, 0.0)), cfg)
    across = 0.09 + (20.0 * math.radians(1.5)) ** 2  # 0.09 + 0.274
    np.testing.assert_allclose(np.diag(cov), (across, 0.09, across), rtol=1e-12)
    assert abs(cov[0, 1]) < 1e-15


def _rot_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array(((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0)))


def _hover_with_pose_errors(carried: bool, seed: int = 7, config: ImmConfig | None = None) -> float:
    """A hovering target 20 m north of a hovering vehicle whose state estimate wanders as a
    GNSS/EKF2 one does (Gauss-Markov over 2 s: position 0.3 m, heading 1.5 deg; velocity 0.15
    m/s over 1 s) and whose gyro has a 3 mrad/s bias and 3 mrad/s of white noise; the image
    places the target to centimetres across the line of sight. The target is placed from the
    pose :class:`CarriedPose` carries (``carried``) or from the estimate's pose; returns the
    RMS of the estimated acceleration (m/s^2) over the last 8 s."""
    rng = np.random.default_rng(seed)
    imm = TargetMotionImm(config)
    image_cov = np.diag([0.02**2, 1.0, 0.02**2])
    err, yaw, verr, out = np.zeros(3), 0.0, np.zeros(3), []
    k, kv = math.exp(-DT / 2.0), math.exp(-DT)
    rel_true = np.array([0.0, 20.0, 0.0])
    for i in range(round(10.0 / DT)):
        t = i * DT
        err = k * err + math.sqrt(1 - k * k) * 0.3 * rng.standard_normal(3)
        yaw = k * yaw + math.sqrt(1 - k * k) * math.radians(1.5) * rng.standard_normal()
        verr = kv * verr + math.sqrt(1 - kv * kv) * 0.15 * rng.standard_normal(3)
        gyro = np.array([0.0, 0.0, 3e-3]) + 3e-3 * rng.standard_normal(3)
        p_est, R_est = np.array([0.0, 0.0, 10.0]) + err, _rot_z(yaw)
        if carried:
            cam, R_WB = imm.pose.step(t, p_est, verr, R_est, gyro)
        else:
            cam, R_WB = p_est, R_est
        e = imm.update(t, cam + R_WB @ rel_true, image_cov, np.zeros(3), cam)
        if t > 2.0:
            out.append(np.linalg.norm(e.accel_enu_m_s2))
    return math.sqrt(float(np.mean(np.square(out))))


def test_the_vehicles_own_pose_errors_are_not_taken_for_a_manoeuvre():
    for seed in (7, 8):
        assert _hover_with_pose_errors(carried=True, seed=seed) < 0.1  # 0.045-0.048
        # the estimate's own wander, taken with the carried pose's small uncertainty: 0.3-0.6
        assert _hover_with_pose_errors(carried=False, seed=seed) > 0.2


def test_the_carried_pose_integrates_the_velocity_and_the_gyro():
    pose = CarriedPose()
    R0 = _rot_z(0.3)
    p, R = pose.step(1.0, np.array([1.0, 2.0, 3.0]), np.zeros(3), R0, np.zeros(3))
    np.testing.assert_allclose(p, (1.0, 2.0, 3.0))
    for i in range(1, 101):  # 1 s at 2 m/s east, yawing at 0.5 rad/s; the estimate ignored
        p, R = pose.step(1.0 + 0.01 * i, np.full(3, 99.0), np.array([2.0, 0.0, 0.0]), np.eye(3),
                         np.array([0.0, 0.0, 0.5]))  # fmt: skip
    np.testing.assert_allclose(p, (3.0, 2.0, 3.0), atol=1e-12)
    np.testing.assert_allclose(R, _rot_z(0.8), atol=1e-12)
    held = pose.step(2.0, np.zeros(3), np.array([np.nan, 0.0, 0.0]), np.eye(3), np.zeros(3))
    np.testing.assert_allclose(held[0], (3.0, 2.0, 3.0), atol=1e-12)
    pose.reset()
    p, _ = pose.step(3.0, np.array([5.0, 6.0, 7.0]), np.zeros(3), np.eye(3), np.zeros(3))
    np.testing.assert_allclose(p, (5.0, 6.0, 7.0))


def test_the_stacked_filters_mix_as_filterpys_imm():
    """The same stream through filterpy's IMMEstimator over three KalmanFilters with the same
    models: every estimate equal to 1e-9."""
    from filterpy.kalman import IMMEstimator, KalmanFilter

    from onboard.estimation import imm as imm_module

    cfg = ImmConfig()
    rng = np.random.default_rng(11)
    ours = TargetMotionImm(cfg)
    p, v = np.array([0.0, 20.0, 10.0]), np.array([4.0, 0.0, 0.0])
    ref = None
    for k in range(150):
        t = k * DT
        if t > 2.0:
            w = 3.0 / 4.0 * DT
            v = np.array(
                [
                    math.cos(w) * v[0] - math.sin(w) * v[1],
                    math.sin(w) * v[0] + math.cos(w) * v[1],
                    0.0,
                ]
            )
        p = p + v * DT
        z = p + rng.multivariate_normal(np.zeros(3), R_MEAS)
        est = ours.update(t, z, R_MEAS, v)
        if ref is None:
            filters = []
            for _ in MODELS:
                kf = KalmanFilter(dim_x=9, dim_z=3)
                kf.x = np.concatenate([z, v, np.zeros(3)])
                kf.P = np.zeros((9, 9))
                kf.P[0:3, 0:3] = R_MEAS + cfg.min_position_sigma_m**2 * np.eye(3)
                kf.P[3:6, 3:6] = 4.0 * np.eye(3)
                kf.P[6:9, 6:9] = cfg.initial_accel_sigma_m_s2**2 * np.eye(3)
                kf.H = np.hstack([np.eye(3), np.zeros((3, 6))])
                filters.append(kf)
            ref = IMMEstimator(
                filters, np.array(cfg.initial_probabilities), np.array(cfg.switching)
            )
        else:
            x = ref.filters[2].x
            vh2 = float(x[3] ** 2 + x[4] ** 2)
            omega = float(x[3] * x[7] - x[4] * x[6]) / vh2 if vh2 > 0.25 else 0.0
            omega = min(max(omega, -cfg.max_turn_rad_s), cfg.max_turn_rad_s)
            cv, ca, ct = ref.filters
            cv.F, cv.Q = imm_module._cv_matrices(DT, cfg.q_cv_m_s2)
            ca.F, ca.Q = imm_module._ca_matrices(DT, cfg.q_ca_m_s3)
            ct.F, ct.Q = imm_module._ct_matrices(DT, cfg.q_ct_m_s3, omega)
            ref.predict()
            for kf in ref.filters:
                kf.R = R_MEAS + cfg.min_position_sigma_m**2 * np.eye(3)
            ref.update(z)
        np.testing.assert_allclose(est.accel_enu_m_s2, ref.x[6:9], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(est.velocity_enu_m_s, ref.x[3:6], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(est.probabilities, ref.mu, rtol=1e-9, atol=1e-12)
        assert est.accel_var_m2_s4 == pytest.approx(float(np.trace(ref.P[6:9, 6:9])), rel=1e-9)
