"""The onboard runtime as the SITL (or a vehicle) flies it, in-process: the target diameter
parameter reaches the runtime's DKF, and the attitude handed to the loop is propagated from
PX4's sample time to the tick."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.camera_model import CameraModel
from onboard.datatypes import Detection
from onboard.estimation.dkf import DelayedKalmanFilter
from onboard.geometry import (
    attitude_from_yaw_pitch_roll,
    propagate_attitude,
    quat_to_rotmat,
    rot_x,
    rot_z,
    rotmat_to_quat,
)
from onboard.link.fc_state import MAX_PROPAGATION_S, FcState, state_at
from onboard.link.params import PARAM_IDS, ParamTable, mavlink_param_id
from onboard.runtime.runner import OnboardRuntime, RuntimeConfig

from .sitl_rig import free_port


def _runtime(tmp_path) -> OnboardRuntime:
    cfg = RuntimeConfig(
        fc_url=f"udpout:127.0.0.1:{free_port()}",
        camera="sitl://127.0.0.1:9",  # never opened: run() is not called
        gcs_url=f"udpout:127.0.0.1:{free_port()}",  # PARAM_VALUE goes out to nobody
        params_path=tmp_path / "params.toml",
    )
    return OnboardRuntime(cfg, log=lambda _s: None)


def _balloon(cam: CameraModel, range_m: float, diameter_m: float) -> Detection:
    """A whole balloon straight ahead at ``range_m`` (its true apparent size)."""
    r_px = cam.f_px * 0.5 * diameter_m / math.sqrt(range_m**2 - (0.5 * diameter_m) ** 2)
    u, v = cam.cu_px, cam.cv_px
    return Detection(0.0, (u, v), (u - r_px, v - r_px, 2 * r_px, 2 * r_px), math.pi * r_px**2)


# ---------------------------------------------------------------------- target diameter
def test_target_diameter_is_a_parameter_named_in_px4_style():
    assert PARAM_IDS["TGT_DIAM_M"] == mavlink_param_id("TGT_DIAM_M") == "PRG_TGT_DIAM"
    table = ParamTable()
    assert table.runtime.TGT_DIAM_M == 0.3  # the outdoor balloon, as before
    for bad in (0.0, -0.16, 5.0, math.nan):
        ok, _ = table.set("TGT_DIAM_M", bad, flying=False)
        assert not ok and table.runtime.TGT_DIAM_M == 0.3
    assert table.set("TGT_DIAM_M", 0.16, flying=True)[0] is False  # not in flight
    assert table.set("TGT_DIAM_M", 0.16, flying=False) == (True, "")
    assert table.runtime.dkf_config().target_diameter_m == 0.16


def test_the_runtime_dkf_ranges_an_indoor_balloon_with_its_diameter(tmp_path):
    """A 0.16 m balloon 5 m ahead: with the default 0.3 m the runtime's DKF puts it at about
    9.4 m (0.3 / 0.16 x 5); with PRG_TGT_DIAM = 0.16 at 5 m (apparent-size range, 15 %
    measurement noise: the first fusion lands within 5 %)."""
    (tmp_path / "params.toml").write_text("PRG_TGT_DIAM = 0.16\n")
    rt = _runtime(tmp_path)
    try:
        rt._build_loop(640, 480)
        assert rt.loop.dkf.config.target_diameter_m == 0.16
        cam = rt.loop.camera
        ranges = {}
        for name, cfg in (("param", rt.loop.dkf.config), ("default", None)):
            dkf = DelayedKalmanFilter(cam, cfg)
            dkf.predict(0.0, np.zeros(3), np.zeros(3), quat_to_rotmat([1, 0, 0, 0]) @ cam.R_BC)
            dkf.fuse(_balloon(cam, 5.0, 0.16))
            ranges[name] = dkf.depth_velocity()[0]
        print(f"0.16 m balloon at 5 m: DKF range {ranges}")
        assert ranges["param"] == pytest.approx(5.0, rel=0.05)
        assert ranges["default"] == pytest.approx(5.0 * 0.3 / 0.16, rel=0.05)
        # set over MAVLink on the ground: the DKF takes it at once
        rt.ground._param_set("PRG_TGT_DIAM", 0.5)
        assert rt.loop.dkf.config.target_diameter_m == 0.5
        assert "PRG_TGT_DIAM = 0.5" in (tmp_path / "params.toml").read_text()
    finally:
        rt.fc.link.close()
        rt.ground.link.close()


# ---------------------------------------------------------------------- attitude to the tick
def test_propagate_attitude_is_a_body_frame_rotation_at_constant_rates():
    q0 = rotmat_to_quat(attitude_from_yaw_pitch_roll(0.3, -0.2, 0.1))
    R0 = quat_to_rotmat(q0)
    assert np.array_equal(propagate_attitude(q0, np.array([1.0, 2.0, 3.0]), 0.0), q0)
    q = propagate_attitude(q0, np.array([0.0, 0.0, 2.0]), 0.05)
    assert np.allclose(quat_to_rotmat(q), R0 @ rot_z(0.1), atol=1e-12)
    q = propagate_attitude(q0, np.array([-4.0, 0.0, 0.0]), 0.025)
    assert np.allclose(quat_to_rotmat(q), R0 @ rot_x(-0.1), atol=1e-12)
    assert float(q @ q) == pytest.approx(1.0, abs=1e-12)
    back = propagate_attitude(q, np.array([-4.0, 0.0, 0.0]), -0.025)
    assert np.allclose(quat_to_rotmat(back), R0, atol=1e-12)


def test_state_at_carries_the_attitude_to_the_tick_with_the_latest_gyro():
    q0 = np.array([1.0, 0.0, 0.0, 0.0])
    f = FcState(pos_enu_m=np.zeros(3), vel_enu_m_s=np.zeros(3), q_wxyz=q0)
    f.rates_flu_rad_s = np.array([0.0, 0.0, 1.0])
    assert np.array_equal(state_at(f, 0.02).attitude_wxyz, q0)  # no sample time: as received

    def yaw(s) -> float:
        R = quat_to_rotmat(s.attitude_wxyz)
        return math.atan2(R[1, 0], R[0, 0])

    f.q_time_s = 1.000
    assert yaw(state_at(f, 1.004)) == pytest.approx(0.004, abs=1e-12)  # the attitude's rates
    f.gyro_flu_rad_s = np.array([0.0, 0.0, -2.0])  # then the newest gyro sample
    assert yaw(state_at(f, 1.004)) == pytest.approx(-0.008, abs=1e-12)
    assert yaw(state_at(f, 0.990)) == 0.0  # a tick before the sample: nothing to carry
    assert yaw(state_at(f, 1.5)) == pytest.approx(-2.0 * MAX_PROPAGATION_S, abs=1e-12)
    assert state_at(f, 1.004).time_s == 1.004
    f.gyro_flu_rad_s = np.array([0.0, 0.0, 1e6])  # not a gyro reading: not propagated
    assert np.array_equal(state_at(f, 1.004).attitude_wxyz, q0)


def test_the_state_says_how_far_its_attitude_was_carried():
    # the loop re-bases its LOS change on an attitude that is not of the tick (a stall)
    f = FcState(pos_enu_m=np.zeros(3), vel_enu_m_s=np.zeros(3), q_wxyz=np.array([1.0, 0, 0, 0]))
    assert state_at(f, 1.0).attitude_time_s is None  # no sample time: taken as the tick's
    f.q_time_s, f.gyro_flu_rad_s = 1.000, np.array([0.0, 0.0, 1.0])
    assert state_at(f, 1.004).attitude_time_s == pytest.approx(1.004, abs=1e-12)
    assert state_at(f, 1.5).attitude_time_s == pytest.approx(1.0 + MAX_PROPAGATION_S, abs=1e-12)
    f.gyro_flu_rad_s = np.array([0.0, 0.0, 1e6])  # not propagated: of its sample time
    assert state_at(f, 1.004).attitude_time_s == 1.000


def test_the_attitude_paired_with_the_image_estimate_is_the_tick_s():
    """A vehicle yawing and rolling at 2-3 rad/s, PX4's attitude at 200 Hz arriving 1 ms
    after its sample, ticks at 200 Hz out of phase (seeded): the attitude the loop gets was
    on average 3.5 ms old, ~0.5 deg at these rates; propagated it is within 0.01 deg."""
    rng = np.random.default_rng(11)
    w_flu = np.array([2.0, 0.0, 3.0])

    def truth(t: float) -> np.ndarray:
        return propagate_attitude(np.array([1.0, 0.0, 0.0, 0.0]), w_flu, t)

    def angle_deg(qa, qb) -> float:
        dR = quat_to_rotmat(qa).T @ quat_to_rotmat(qb)
        return math.degrees(math.acos(min(1.0, (np.trace(dR) - 1.0) / 2.0)))

    f = FcState(pos_enu_m=np.zeros(3), vel_enu_m_s=np.zeros(3))
    raw, propagated = [], []
    for k in range(400):
        now = 0.005 * k + float(rng.uniform(0.0, 0.005))
        sample_t = 0.005 * math.floor((now - 0.001) / 0.005)  # the newest that has arrived
        f.q_wxyz, f.q_time_s, f.rates_flu_rad_s = truth(sample_t), sample_t, w_flu
        f.gyro_flu_rad_s = w_flu + rng.normal(0.0, 3e-3, 3)  # white gyro noise
        raw.append(angle_deg(truth(now), f.q_wxyz))
        propagated.append(angle_deg(truth(now), state_at(f, now).attitude_wxyz))
    print(f"attitude error at the tick: {np.mean(raw):.3f} deg as received, "
          f"{np.mean(propagated):.4f} deg propagated")  # fmt: skip
    assert np.mean(raw) == pytest.approx(math.degrees(math.hypot(2.0, 3.0) * 0.0035), rel=0.15)
    assert max(propagated) < 0.01
