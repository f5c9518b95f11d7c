"""One sortie, three producers: the simulator's frames, the frames replay rebuilds from its
recording, and the frames live mode builds from the same ticks sent as the onboard
component's telemetry (float32 ``DEBUG_FLOAT_ARRAY``) are the same frames, to the precision
the recording and the telemetry carry; and the one snapshot builder shows them alike."""

import ast
import dataclasses
import math
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from groundstation.app import live_recording
from groundstation.app.live import TARGET_DIAMETER_M, LiveSession
from groundstation.app.live_link import LINK_TIMEOUT_S
from groundstation.app.replay import ReplayPlayer
from groundstation.app.snapshot import frame_snapshot
from groundstation.recording.reader import inspect_log, iter_messages
from groundstation.recording.writer import SortieRecorder
from groundstation.scenario import load_scenario
from groundstation.sim.simulation import Simulation
from onboard.frames import Frame, FrameList
from onboard.link import telemetry as tm

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    d = tmp_path_factory.mktemp("logs")
    rec, frames = SortieRecorder(d, mode="local"), FrameList()
    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 4, observers=[rec, frames])
    result = sim.run()
    assert result.outcome == "HIT" and rec.closed and rec.error is None
    assert sim.records == frames.frames  # the campaigns' records are the same frames
    return sim, frames, rec.path


REL = {"rel": 0.0}  # relative precision of the producer under test (float32, %.6g)


def close(a, b, tol: float) -> bool:
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = (a == b) | (np.abs(a - b) <= tol + REL["rel"] * np.abs(a))
    return a.shape == b.shape and bool(np.all(ok))


def assert_same_frame(a: Frame, b: Frame, tol: dict[str, float], cov: bool = True) -> None:
    """``tol``: per quantity, the precision the second producer's source carries."""
    where = f"at t = {a.time_s:.3f} s"
    REL["rel"] = tol["rel"]
    assert abs(a.time_s - b.time_s) <= tol["time"], where
    assert close(a.vehicle_p_enu_m, b.vehicle_p_enu_m, tol["pos"]), where
    assert close(a.vehicle_q_wxyz, b.vehicle_q_wxyz, tol["quat"]), where
    assert close(a.vehicle_v_enu_m_s, b.vehicle_v_enu_m_s, tol["pos"]), where
    assert close(a.target_p_enu_m, b.target_p_enu_m, tol["pos"]), where
    ta, tb = a.telemetry, b.telemetry
    assert (ta.mode, ta.law, ta.dkf_lost) == (tb.mode, tb.law, tb.dkf_lost), where
    for name in ("e_est_px", "e_rate_est_px_s"):
        assert close(getattr(ta, name), getattr(tb, name), tol["px"]), (name, where)
    for name in ("los_elev_rad", "los_azim_rad", "vel_elev_rad", "vel_azim_rad"):
        x, y = getattr(ta, name), getattr(tb, name)
        assert (math.isnan(x) and math.isnan(y)) or close(x, y, tol["rad"]), (name, where)
    assert close(ta.accel_desired_enu_m_s2, tb.accel_desired_enu_m_s2, tol["acc"]), where
    assert close(ta.accel_normal_desired_m_s2, tb.accel_normal_desired_m_s2, tol["acc"])
    assert close(ta.yaw_rate_cmd_rad_s, tb.yaw_rate_cmd_rad_s, tol["rad"]), where
    assert close(ta.command.body_rates_flu_rad_s, tb.command.body_rates_flu_rad_s, tol["cmd"])
    assert abs(ta.command.thrust_normalised - tb.command.thrust_normalised) <= tol["cmd"]
    since_a, since_b = (min(x, 1e6) for x in (ta.dkf_time_since_detection_s,
                                              tb.dkf_time_since_detection_s))  # fmt: skip
    assert close(since_a, since_b, tol["time"]), where
    da, db = a.detection, b.detection
    assert (da is None) == (db is None), where
    if da is not None:
        assert close(da.center_px, db.center_px, tol["px"]), where
        assert abs(da.capture_time_s - db.capture_time_s) <= tol["time"], where
    assert close(a.dkf_state_px, b.dkf_state_px, tol["px"]), where
    if cov:
        assert close(a.dkf_cov_diag, b.dkf_cov_diag, tol["px"]), where
    assert (a.acquired, a.gains, a.guard_trips) == (b.acquired, b.gains, b.guard_trips), where


def test_replay_rebuilds_the_simulators_frames(flown):
    sim, frames, path = flown
    player = ReplayPlayer(path)
    at = {round(f.time_s, 6): f for f in frames.frames}
    # /dkf and the target are recorded at half the pose-and-control rate: a frame recorded
    # whole every tenth tick (10 Hz)
    assert len(player.td) >= 10 * sim.time_s - 2
    # JSON precision of the recording: positions %.4f, angles 6 significant digits, ...
    tol = {"time": 2e-6, "pos": 6e-5, "quat": 6e-7, "px": 6e-4, "rad": 2e-5, "acc": 6e-5,
           "cmd": 6e-6, "rel": 5e-6}  # fmt: skip
    for t in player.td:
        sim_frame, replayed = at[round(t, 6)], player.frame(t)
        assert_same_frame(sim_frame, replayed, tol)
        assert replayed.normal_accel_m_s2 == pytest.approx(sim_frame.normal_accel_m_s2, 1e-5)


def _heard(live: LiveSession, f: Frame, k: int, cam) -> Frame:
    """Tick ``k`` of a flown sortie as live mode hears it (the onboard component's telemetry
    and the target's report, at ground time ``k`` s): the frame it builds. The first starts the
    recording, as an accepted start does."""
    tel = f.telemetry
    vals = {
        "t_s": f.time_s,
        "state": 4,
        "law": tm.LAW_CODES.index(tel.law),
        "image_w_px": cam.width_px,
        "image_h_px": cam.height_px,
        "f_px": cam.f_px,
        "guard_trips": f.guard_trips,
        **tm.loop_values(tel),
        **tm.detection_values(f.detection, cam),
        **tm.dkf_values(f.dkf_state_px, f.dkf_cov_diag),
        **tm.pose_values(f.vehicle_p_enu_m, f.vehicle_v_enu_m_s, f.vehicle_q_wxyz),
    }
    data = np.asarray(tm.pack(vals), dtype=np.float32)  # what DEBUG_FLOAT_ARRAY holds
    vehicle = live.vehicle  # what the link reports
    with vehicle.lock:
        vehicle.gains = f.gains  # the vehicle's gain parameters
        vehicle.target_p = [float(c) for c in np.float32(f.target_p_enu_m)]
        vehicle.target_rx_s = float(k)  # reported with this tick
        vehicle.onboard_rx_s = time.monotonic()  # the onboard component is heard
        vehicle._telemetry(tm.unpack(data), float(k))
        got = live.frame()
        if k == 0:  # the operator's start, accepted: recording from here
            vehicle.params["LAW"] = float(tm.LAW_CODES.index(tel.law))
            live._start_recording()
    return got


def _udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_live_mode_builds_the_same_frames_from_the_telemetry(flown, tmp_path):
    """...and records them: the live recording replays as the simulator's frames too."""
    sim, frames, _ = flown
    live = LiveSession(f"udpin:127.0.0.1:{_udp_port()}", log_dir=tmp_path)
    cam = sim.loop.camera  # the vehicle reports its detections with the camera it believes
    # float32 (24-bit mantissa): relative 6e-8, and what the subtractions leave
    tol = {"time": 1e-6, "pos": 1e-6, "quat": 1e-7, "px": 1e-5, "rad": 1e-7, "acc": 1e-6,
           "cmd": 1e-7, "rel": 1.2e-7}  # fmt: skip
    n_accel = errors = 0
    try:
        for k, f in enumerate(frames.frames):
            got = _heard(live, f, k, cam)
            assert_same_frame(f, got, tol)
            if got.normal_accel_m_s2 is not None and k > 0:
                # live differentiates the velocity between ticks: not the instantaneous value
                n_accel += 1
                errors += abs(got.normal_accel_m_s2 - f.normal_accel_m_s2) > 1.0
        with live.vehicle.lock:
            live._finish_recording("the test ended")
    finally:
        live.close()
    assert n_accel == len(frames.frames) - 1 and errors <= 0.05 * n_accel
    (path,) = tmp_path.glob("*_live_png.mcap")
    player = ReplayPlayer(path)
    assert len(player.td) >= len(frames.frames) // 2 - 2  # /dkf every second tick
    tol = {
        "time": 4e-6,
        "pos": 7e-5,
        "quat": 7e-7,
        "px": 7e-4,
        "rad": 2e-5,
        "acc": 7e-5,
        "cmd": 7e-6,
        "rel": 6e-6,
    }  # fmt: skip  (float32, then the recording's JSON)
    for t in player.td[1:]:  # the first message was before the start
        sim_frame = min(frames.frames, key=lambda f, t=t: abs(f.time_s - t))
        replayed = player.frame(t)
        replayed = dataclasses.replace(replayed, time_s=sim_frame.time_s)  # float32 clock
        assert_same_frame(sim_frame, replayed, tol)


def test_a_telemetry_gap_is_an_event_and_the_recording_goes_on(flown, tmp_path, monkeypatch):
    """The ground link silent for longer than its timeout in mid-sortie (a loaded ground
    computer, a radio fade) leaves the recording open and the ticks heard after it are
    recorded; only a link silent for LINK_GIVE_UP_S ends it."""
    monkeypatch.setattr(live_recording, "LINK_GIVE_UP_S", 1.0)
    sim, frames, _ = flown
    live = LiveSession(f"udpin:127.0.0.1:{_udp_port()}", log_dir=tmp_path)
    v, half = live.vehicle, len(frames.frames) // 2
    try:
        for k, f in enumerate(frames.frames):
            _heard(live, f, k, sim.loop.camera)
            with v.lock:
                if k == half:  # nothing heard for longer than the link's timeout
                    v.onboard_rx_s = time.monotonic() - LINK_TIMEOUT_S - 0.1
                    assert not v.link_up()
                live._maybe_finish(time.monotonic())
                assert live.rec is not None  # main: closed "link to the onboard lost"
        with v.lock:  # then silent for good
            v.onboard_rx_s = time.monotonic() - LINK_TIMEOUT_S - 0.1
            live._maybe_finish(time.monotonic())
            assert live.rec is not None
            live._maybe_finish(time.monotonic() + 1.0)
            assert live.rec is None
    finally:
        live.close()
    (path,) = tmp_path.glob("*_live_png.mcap")
    info = inspect_log(path)
    assert info.metadata["outcome"]["reason"] == '"link to the onboard lost"'
    assert info.duration_s == pytest.approx(frames.frames[-1].time_s, abs=1e-3)
    events = [str(m) for topic, _, m in iter_messages(path) if topic == "/events"]
    assert sum("telemetry link lost" in e for e in events) == 2
    assert sum("telemetry link back after" in e for e in events) == 1


def test_one_snapshot_builder_shows_the_three_alike(flown):
    sim, frames, path = flown
    player = ReplayPlayer(path)
    t = player.td[len(player.td) // 2]
    f = next(x for x in frames.frames if abs(x.time_s - t) < 1e-6)
    from_sim = frame_snapshot(f, sim.camera_model, sim.scenario.target.diameter_m)
    from_replay = frame_snapshot(player.frame(t), player.camera, player.diameter_m, t_s=t)
    assert from_sim.keys() == from_replay.keys()
    assert from_replay["normal_vel_m_s"] is not None  # replay had none before the frames
    for key in ("range_m", "speed_m_s", "normal_vel_m_s", "normal_accel_m_s2", "k_a"):
        assert from_replay[key] == pytest.approx(from_sim[key], abs=2e-4), key
    assert from_replay["e_raw_px"] == pytest.approx(from_sim["e_raw_px"], abs=1e-3)
    assert from_replay["mode"] == from_sim["mode"] == "tracking"
    assert from_replay["image"] == from_sim["image"]
    assert TARGET_DIAMETER_M > 0


def _imports(package: Path) -> set[str]:
    """Absolute names of the modules a package's files import (relative imports resolved)."""
    out = set()
    for path in package.rglob("*.py"):
        mod = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                out.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = mod.split(".")[: len(mod.split(".")) - node.level] if node.level else []
                out.add(".".join([*base, node.module or ""]).rstrip("."))
    return out


def test_producers_and_consumers_stand_side_by_side():
    """sim/ and recording/ share only the frames (onboard/frames.py); onboard never imports
    the ground station."""
    sim, recording = (
        _imports(ROOT / "groundstation" / "sim"),
        _imports(ROOT / "groundstation" / "recording"),
    )
    assert not any(m.startswith("groundstation.recording") for m in sim), sim
    assert not any(m.startswith("groundstation.sim") for m in recording), recording
    assert "onboard.frames" in sim and "onboard.channels.builder" in recording
    assert not any(m.startswith("groundstation") for m in _imports(ROOT / "onboard"))
