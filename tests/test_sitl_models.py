"""The SITL vehicle tells the onboard computer what a real PX4 would: the simulator's state-
estimate model (``[estimate]``) and detector faults (``[camera]``), the same implementation,
seeded, switchable with ``--set``. Stepped here without a clock or sockets: a recording link
and camera stand in for MAVLink and the camera server."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.scenario import load_scenario, parse_overrides, with_overrides
from groundstation.sitl.telemetry import RATES_HZ
from groundstation.sitl.vehicle import PHYSICS_HZ, SitlVehicle, sitl_estimate_spec
from onboard.geometry import quat_to_rotmat
from onboard.link.px4 import MODE_OFFBOARD, mavlink, ned_to_enu, quat_ned_frd_to_enu_flu
from onboard.perception import RedBalloonDetector


class RecordingLink:
    """Takes what the SITL sends (MAVLink messages), in order."""

    def __init__(self) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.sent: list = []

    def send(self, msg) -> bool:
        msg.pack(self.mav)  # the header: who sent it
        self.sent.append(msg)
        return True

    def heartbeat(self, *_a) -> None:
        pass

    def statustext(self, *_a) -> None:
        pass


class RecordingCamera:
    clients = 1

    def __init__(self) -> None:
        self.frames: list[tuple[np.ndarray, float, float]] = []

    def publish(self, image, capture_time_s: float, age_s: float) -> None:
        self.frames.append((image, capture_time_s, age_s))


class Quiet:
    def write(self, _s) -> None:
        pass

    def flush(self) -> None:
        pass


def _vehicle(*overrides: str, scenario: str = "static-ahead-20m", seed: int = 4):
    from groundstation.sitl.vehicle import SitlOptions

    sc = with_overrides(load_scenario(scenario), parse_overrides(list(overrides)))
    link, cam = RecordingLink(), RecordingCamera()
    return SitlVehicle(sc, link, cam, SitlOptions(seed=seed), out=Quiet()), link, cam


def _fly(veh: SitlVehicle, seconds: float, each_step=None) -> None:
    for _ in range(round(seconds * PHYSICS_HZ)):
        veh.step()
        veh._send_due(veh.time_s)
        if each_step is not None:
            each_step(veh)


def _reports(link: RecordingLink, kind: str) -> list:
    return [m for m in link.sent if m.get_type() == kind and m.get_srcSystem() == 1]


def test_the_estimate_model_is_on_by_default_and_the_same_switch_turns_it_off():
    truth: dict[int, tuple] = {}

    def keep(v):
        truth[int(v.time_s * 1000)] = (list(v.vehicle.p), list(v.vehicle.v), list(v.vehicle.q))

    ideal, link0, _ = _vehicle("estimate.enabled=false")
    _fly(ideal, 2.0, keep)
    assert ideal.estimate is None
    assert len(_reports(link0, "LOCAL_POSITION_NED")) >= 190  # 100 Hz
    for m in _reports(link0, "LOCAL_POSITION_NED"):  # the truth, exactly
        p, v, _q = truth[m.time_boot_ms]
        assert np.allclose(ned_to_enu((m.x, m.y, m.z)), p, atol=1e-5)
        assert np.allclose(ned_to_enu((m.vx, m.vy, m.vz)), v, atol=1e-5)

    truth.clear()
    real, link, _ = _vehicle()
    _fly(real, 20.0, keep)
    assert real.estimate is not None
    pos_err, vel_err, att_err_deg = [], [], []
    for m in _reports(link, "LOCAL_POSITION_NED"):
        p, v, _q = truth[m.time_boot_ms]
        pos_err.append(np.array(ned_to_enu((m.x, m.y, m.z))) - p)
        vel_err.append(np.array(ned_to_enu((m.vx, m.vy, m.vz))) - v)
    for m in _reports(link, "ATTITUDE_QUATERNION"):
        q = quat_ned_frd_to_enu_flu((m.q1, m.q2, m.q3, m.q4))
        dR = quat_to_rotmat(np.array(truth[m.time_boot_ms][2])).T @ quat_to_rotmat(q)
        att_err_deg.append(math.degrees(math.acos(min(1.0, (np.trace(dR) - 1.0) / 2.0))))
    pos_rms = float(np.sqrt(np.mean(np.square(pos_err))))
    vel_rms = float(np.sqrt(np.mean(np.square(vel_err))))
    att_rms = float(np.sqrt(np.mean(np.square(att_err_deg))))
    print(f"hover 20 s, seed 4: pos {pos_rms:.3f} m, vel {vel_rms:.3f} m/s, att {att_rms:.3f} deg")
    # the model's sigmas are 0.05 m, 0.05 m/s per axis and 0.2 deg per axis (|error| of three
    # axes: rms 0.35 deg); Gauss-Markov over 10-20 correlation times: within a factor of ~2.5
    assert 0.02 <= pos_rms <= 0.12, pos_rms
    assert 0.02 <= vel_rms <= 0.12, vel_rms
    assert 0.14 <= att_rms <= 0.8, att_rms


def test_position_and_attitude_lag_less_the_streams_own_age():
    """Errors switched off but the lags: what is reported is the truth the modelled lag less
    half a stream period ago (15 ms and 7.5 ms with the defaults), seen in a climb."""
    spec = sitl_estimate_spec(load_scenario("static-ahead-20m").estimate, RATES_HZ)
    assert spec.lag_s == pytest.approx(0.015) and spec.att_lag_s == pytest.approx(0.0075)
    quiet = [
        f"estimate.{k}=0"
        for k in ("pos_noise_m", "vel_noise_m_s", "att_noise_deg", "gyro_bias_rad_s")
    ] + ["estimate.gyro_bias_walk_rad_s_sqrt_s=0"]
    veh, link, _ = _vehicle(*quiet)
    hist: dict[int, tuple] = {}

    def keep(v):
        hist[v.step_index] = (list(v.vehicle.v), list(v.vehicle.w))

    veh.hold_p[2] += 3.0  # PX4's hold climbs to a point 3 m up
    _fly(veh, 2.0, keep)
    lag_steps = round(spec.lag_s * PHYSICS_HZ)  # 9
    n = accelerating = 0
    for m in _reports(link, "LOCAL_POSITION_NED"):
        k = round(m.time_boot_ms * PHYSICS_HZ / 1000)
        if k - lag_steps in hist:
            v_now, v_then = hist[k][0][2], hist[k - lag_steps][0][2]
            # interpolated between the samples the streams took (200 Hz): within 1 mm/s
            assert -m.vz == pytest.approx(v_then, abs=1e-3), (k, v_now, v_then)
            n += 1
            accelerating += abs(v_now - v_then) > 0.01  # where the lag shows
    assert n > 150 and accelerating > 10, (n, accelerating)


def test_gyro_bias_reaches_the_imu_stream_and_the_stamps_carry_the_camera_offset():
    veh, link, cam = _vehicle()
    est = veh.estimate
    _fly(veh, 6.0)
    imu = _reports(link, "HIGHRES_IMU")
    rates = np.array([[m.xgyro, -m.ygyro, -m.zgyro] for m in imu[-400:]])  # FRD -> FLU
    bias = est.gyro_bias.value
    # hovering: the mean gyro is the bias (white noise 3e-3 rad/s over 400 samples: 1.5e-4)
    assert np.allclose(rates.mean(axis=0), bias, atol=1e-3), (rates.mean(axis=0), bias)
    assert np.linalg.norm(bias) > 1e-3  # seed 4 draws a bias well above that tolerance
    # each frame's capture stamp: the capture (on the camera's 1/rate grid) + offset + jitter
    period = 1.0 / veh.scenario.camera.rate_hz
    errs = np.array([c - period * round(c / period) for _, c, _ in cam.frames])
    assert len(errs) > 100
    print(f"camera offset {1000 * est.camera_offset_s:.2f} ms, stamp errors mean "
          f"{1000 * errs.mean():.2f} ms, sd {1000 * errs.std():.2f} ms")  # fmt: skip
    assert errs.mean() == pytest.approx(est.camera_offset_s, abs=3e-4)
    assert errs.std() == pytest.approx(veh.scenario.estimate.camera_stamp_jitter_s, rel=0.25)
    assert all(age >= 0.0 for _, _, age in cam.frames)


def test_setpoints_reach_the_motors_late_and_scaled():
    veh, _, _ = _vehicle()
    est = veh.estimate
    veh.custom_mode, veh.last_setpoint_s = MODE_OFFBOARD, 0.0
    _fly(veh, 0.1)
    veh.setpoint, veh.last_setpoint_s = (np.zeros(3), 0.6), veh.time_s
    veh._queue_setpoint(veh.time_s)
    sent_at = veh.time_s
    applied_at = None
    for _ in range(20):
        veh.step()
        if applied_at is None and veh.vehicle.cmd_thrust_n == pytest.approx(
            0.6 * est.thrust_scale * veh.vehicle.params.max_thrust_n
        ):
            applied_at = veh.time_s - veh.dt_s  # the step that applied it
    assert est.thrust_scale != 1.0
    assert applied_at is not None
    assert applied_at - sent_at == pytest.approx(est.command_delay_s, abs=0.5 / PHYSICS_HZ)


def test_detector_faults_drop_bursts_draw_false_blobs_and_hide_small_balloons():
    det = RedBalloonDetector()
    # bursts: with the chain's defaults (mean 5 frames, all dropped) and 10 % burst starts,
    # the stationary drop rate is p / (p + 1/5) = 1/3
    veh, _, cam = _vehicle("camera.burst_probability=0.1", "camera.dropout_probability=0")
    _fly(veh, 10.0)
    frames = veh.faults.frames
    drop = 1.0 - len(cam.frames) / frames
    print(f"bursts: {frames} frames, {drop:.3f} dropped")
    assert drop == pytest.approx(1.0 / 3.0, abs=0.08)
    assert veh.faults.dropped == frames - len(cam.frames) - len(veh._frames)
    # a false red blob in every frame, bigger than the balloon at 20 m: the detector takes it
    veh, _, cam = _vehicle("camera.false_probability=1", "camera.false_blob_px=30")
    _fly(veh, 0.5)
    found = [det.detect(img, c) for img, c, _ in cam.frames]
    assert found and all(d is not None and d.bbox_px[2] > 20 for d in found)
    # the balloon at 20 m is 4.8 px wide: with min_blob_px 15 it is not there to detect
    quiet = ("camera.false_probability=0", "camera.burst_probability=0")  # the other faults off
    veh, _, cam = _vehicle("camera.min_blob_px=15", *quiet)
    _fly(veh, 0.5)
    assert cam.frames and all(det.detect(img, c) is None for img, c, _ in cam.frames)
    assert veh.faults.too_small >= len(cam.frames)
    veh, _, cam = _vehicle("camera.min_blob_px=3", *quiet)
    _fly(veh, 0.5)
    assert cam.frames and all(det.detect(img, c) is not None for img, c, _ in cam.frames)


@pytest.mark.parametrize("vertex_at_boundary", [True, False])
def test_a_pass_whose_closest_point_is_between_two_steps_ends_the_sortie(vertex_at_boundary):
    # the SITL judges the pass as the simulator does (groundstation/sim/physics.py): relative
    # positions (target minus vehicle) bending at the closest point, 0.25 m to the side
    veh, _, _ = _vehicle()
    veh.sortie_start_s = 0.0
    y = 0.25
    path = [(1.0, 0.45, 0.0), (0.0, y, 0.0), (-1.0, 0.45, 0.0), (-2.0, 0.65, 0.0)]
    if not vertex_at_boundary:  # a straight pass: the closest point inside a step
        path = [(1.5, y, 0.0), (0.5, y, 0.0), (-0.5, y, 0.0), (-1.5, y, 0.0)]
    veh.vehicle.p = [0.0, 0.0, 10.0]
    for k, rel in enumerate(path):
        veh.target.p = [rel[0], rel[1], 10.0 + rel[2]]
        veh._track_closest(k * veh.dt_s)
        if k < 2:
            assert veh.result is None  # still closing
    assert veh.result is not None and veh.result["outcome"] == "HIT", veh.result
    assert veh.result["miss_m"] == pytest.approx(y, abs=1e-4)
    assert veh.miss_m <= veh.hit_radius_m
