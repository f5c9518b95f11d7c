import math

import numpy as np
from numpy.testing import assert_allclose

from onboard.camera_model import CameraModel, rotational_flow
from onboard.geometry import (
    attitude_from_yaw_pitch_roll,
    camera_mount_rotation,
    quat_to_rotmat,
    rotation_between,
    rotmat_to_quat,
    wrap_pi,
)


def test_quaternion_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.standard_normal(4)
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        R = quat_to_rotmat(q)
        assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert_allclose(rotmat_to_quat(R), q, atol=1e-12)


def test_yaw_90_faces_north_and_pitch_up_raises_nose(R_north):
    assert_allclose(R_north[:, 0], [0, 1, 0], atol=1e-12)  # body x -> +y
    assert_allclose(R_north[:, 1], [-1, 0, 0], atol=1e-12)  # body left -> -x (west)
    R = attitude_from_yaw_pitch_roll(math.pi / 2, math.radians(10))
    assert R[2, 0] > 0.17  # nose up


def test_rotation_between_including_antiparallel():
    a = np.array([0.0, 0.0, 1.0])
    for b in ([0.0, 1.0, 0.0], [0.6, 0.0, 0.8], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]):
        b = np.array(b)
        R = rotation_between(a, b)
        assert_allclose(R @ a, b, atol=1e-12)
        assert_allclose(R @ R.T, np.eye(3), atol=1e-12)


def test_wrap_pi():
    assert wrap_pi(math.pi) == math.pi
    assert_allclose(wrap_pi(-math.pi), math.pi)
    assert_allclose(wrap_pi(3 * math.pi / 2), -math.pi / 2)
    assert_allclose(wrap_pi(-0.1), -0.1)


def test_camera_mount_forward_pitched_and_portrait():
    R0 = camera_mount_rotation()
    # optical axis along body x, image right = body right (-y), image down = body down (-z)
    assert_allclose(R0 @ [0, 0, 1], [1, 0, 0], atol=1e-12)
    assert_allclose(R0 @ [1, 0, 0], [0, -1, 0], atol=1e-12)
    assert_allclose(R0 @ [0, 1, 0], [0, 0, -1], atol=1e-12)
    Rp = camera_mount_rotation(pitch_up_deg=20)
    assert_allclose(Rp @ [0, 0, 1], [math.cos(0.349066), 0, math.sin(0.349066)], atol=1e-6)
    cam = CameraModel(mount_roll_deg=90)
    # a point to the body's right appears along image -y in portrait; upright() maps it back
    p_body_right = np.array([10.0, -1.0, 0.0])
    u, v = cam.project(cam.R_BC.T @ p_body_right)
    ex, ey = cam.error_px(u, v)
    assert abs(ex) < 1e-9 and ey < 0
    assert cam.upright(ex, ey)[0] > 0 and abs(cam.upright(ex, ey)[1]) < 1e-9


def test_focal_length_from_hfov():
    cam = CameraModel(640, 480, 90.0)
    assert_allclose(cam.f_px, 320.0)
    assert_allclose(cam.vfov_deg, 2 * math.degrees(math.atan(240 / 320)))


def test_rotational_flow_matches_finite_difference(R_north):
    """Rotational columns of L_s (paper eq. 4) against a numerically rotated camera."""
    cam = CameraModel()
    target = np.array([3.0, 20.0, 12.0])
    w = np.array([0.3, -0.5, 0.4])  # body rates, FLU
    dt = 1e-6

    def uv(R):
        return np.array(cam.project((R @ cam.R_BC).T @ target))

    angle = np.linalg.norm(w) * dt
    k = w / np.linalg.norm(w)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    dR = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    fd = (uv(R_north @ dR) - uv(R_north)) / dt
    e = (uv(R_north) - [cam.cu_px, cam.cv_px]) / cam.f_px
    model = np.array(rotational_flow(e[0], e[1], cam.R_BC.T @ w)) * cam.f_px
    assert_allclose(model, fd, rtol=1e-4)


def test_attitude_jump_is_the_rotation_beyond_the_gyros_turn():
    from onboard.geometry import attitude_jump_rad, propagate_rotation, rodrigues

    rng = np.random.default_rng(11)
    for _ in range(200):
        axis = rng.normal(size=3)
        R0 = rodrigues(axis / np.linalg.norm(axis), float(rng.uniform(0, 3.0)))
        w = rng.normal(scale=3.0, size=3)  # rad/s
        dt = float(rng.uniform(0.001, 0.02))
        R1 = propagate_rotation(R0, w, dt)
        assert attitude_jump_rad(R0, R1, *w.tolist(), dt) < 1e-9  # turned as the gyro says
        kick = rng.normal(size=3)
        kick *= 0.01 / np.linalg.norm(kick)  # then 10 mrad more, about any axis
        R2 = R1 @ rodrigues(kick / 0.01, 0.01)
        jump = attitude_jump_rad(R0, R2, *w.tolist(), dt)
        assert abs(jump - 0.01) < 0.0015  # first order in the rotation vectors' difference
        as_python = getattr(attitude_jump_rad, "py_func", attitude_jump_rad)
        assert jump == as_python(R0, R2, *w.tolist(), dt)  # compiled: the same bits
