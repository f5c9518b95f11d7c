"""The whole chain on one machine: ``groundstation sitl`` (a PX4-like vehicle), ``onboard
run`` and the ground station as separate processes talking MAVLink on loopback, and the
faults the onboard runtime must survive. Real time: each test flies for a few seconds."""

from __future__ import annotations

import json
import math
import os
import re
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

from groundstation.recording.reader import inspect_log, iter_messages
from groundstation.scenario import load_scenario
from onboard.link.px4 import mavlink

from .sitl_rig import Rig

MISS_LIMIT_M = 0.3


@pytest.fixture
def rig_factory(tmp_path):
    rigs = []

    def make(**kw) -> Rig:
        rig = Rig(tmp_path, **kw)
        rigs.append(rig)
        return rig

    yield make
    for r in rigs:
        r.close()


def _assert_hit(rig: Rig, result: dict) -> None:
    """A HIT within MISS_LIMIT_M; otherwise the failure carries what explains a miss: both
    processes' logs (the loop's mode changes) and the vehicle loop's timing (stopped for it)."""
    if result["outcome"] == "HIT" and result["miss_m"] <= MISS_LIMIT_M:
        return
    logs = rig.logs()
    stats = rig.close()
    raise AssertionError(f"{result}\n{logs}\n--- onboard loop stats\n{json.dumps(stats)}")


def _no_traceback(rig: Rig) -> None:
    logs = rig.logs()
    assert "Traceback" not in logs, logs


# ---------------------------------------------------------------------- end to end
class GroundStationProcess:
    def __init__(self, tmp, url: str, key_file) -> None:
        self.err = tmp / "gs.log"
        # --port 0: the server takes a free port itself and prints it (a port picked here and
        # closed could be taken by another socket before the server binds it)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "groundstation", "serve", "--port", "0",
             "--mavlink", url, "--signing-key", str(key_file), "--log-dir", str(tmp / "logs"),
             "--data-dir", str(tmp / "data")],
            stdout=subprocess.PIPE, stderr=self.err.open("w"), text=True, cwd=tmp,
            env=dict(os.environ, PYTHONUNBUFFERED="1"),
        )  # fmt: skip
        line = self.proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:(\d+)/\?token=(\S+)", line)
        assert m, f"no URL printed: {line!r} {self.err.read_text()}"
        self.port, self.token = int(m.group(1)), m.group(2)

    def api(self, method: str, path: str, body=None) -> tuple[int, dict]:
        req = urllib.request.Request(
            f"http://127.0.0.1:{self.port}{path}",
            method=method,
            data=None if body is None else json.dumps(body).encode(),
            headers={"Authorization": f"Bearer {self.token}", "Content-Type": "application/json"},
        )
        try:
            with urllib.request.urlopen(req, timeout=15) as r:
                return r.status, json.loads(r.read())
        except urllib.error.HTTPError as e:
            return e.code, json.loads(e.read())

    def wait(self, pred, timeout_s: float, what: str) -> dict:
        end = time.monotonic() + timeout_s
        st = None
        while time.monotonic() < end:
            try:
                st = self.api("GET", "/api/status")[1]
                if pred(st):
                    return st
            except OSError:
                pass  # not listening yet
            time.sleep(0.1)
        raise AssertionError(f"{what}: not within {timeout_s} s; last status {st}")

    def close(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(15)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def test_end_to_end_sitl_onboard_and_ground_station(tmp_path, rig_factory):
    key = tmp_path / "key"
    key.write_text(os.urandom(32).hex())
    # no clutter: a false red blob after the pass can start a new track and hold the end off
    # (the end of an intercept under clutter is its own test's business)
    rig = rig_factory(
        ground=False,
        onboard_args=("--signing-key", str(key)),
        sitl_args=("--set", "camera.false_probability=0"),
    )
    gs = GroundStationProcess(tmp_path, f"udpin:127.0.0.1:{rig.gcs_port}", key)
    try:
        rig.wait_up()  # the 30 s below count from all three processes being up
        st = gs.wait(
            lambda s: (
                s["live"]["onboard_state"] == "ready"
                and s["live"]["params_received"] == s["live"]["params_total"]
                and s["live"]["fc_mode"] == "HOLD"  # PX4's 1 Hz heartbeat, passed through
            ),
            30.0,
            "onboard ready with every parameter read, PX4 holding",
        )
        assert st["live"]["link"] == "up"
        assert st["live"]["signed"] is True
        # a gain over MAVLink: applied only when the vehicle's PARAM_VALUE says so
        code, _ = gs.api("PUT", "/api/gains", {"v_max": 6.0})
        assert code == 200
        gs.wait(lambda s: not s["gains_pending"], 5.0, "PARAM_VALUE for v_max")
        assert gs.api("GET", "/api/gains")[1]["values"]["v_max"] == 6.0
        assert "PRG_V_MAX = 6.0" in rig.params.read_text()  # saved on the vehicle
        # a burst of dropped frames (the detector's faults are on) can take the target out of
        # view between "ready" and the start: the vehicle refuses, and the operator presses again
        deadline = time.monotonic() + 10.0
        while True:
            code, body = gs.api("POST", "/api/live/start")
            refused = code == 409 and "no target in view" in str(body)
            if not refused or time.monotonic() > deadline:
                break
            gs.wait(lambda s: s["live"]["onboard_state"] == "ready", 5.0, "ready again")
        assert code == 200 and body["ack"]["result"] == "accepted", body
        result = rig.sitl_result(timeout_s=25.0)
        _assert_hit(rig, result)
        # the gain took effect: with the default v_max = 12 m/s this pass reaches 7.5 m/s; at
        # 6 m/s it overshoots by a few per cent (6.37 m/s measured at load 5: the real-time
        # rig's late ticks)
        assert result["max_speed_m_s"] <= 6.0 * 1.1, result
        st = gs.wait(lambda s: s["live"]["onboard_state"] == "finished", 15.0, "finished")
        assert st["live"]["rates_hz"].get("DEBUG_FLOAT_ARRAY", 0) >= 20.0
        # braked, then handed back to PX4 (its 1 Hz heartbeat tells the ground)
        gs.wait(lambda s: s["live"]["fc_mode"] == "HOLD", 3.0, "PX4 in HOLD")
        gs.wait(lambda s: s["recording"] is None, 5.0, "recording closed")
    finally:
        gs.close()
        stats = rig.close()
    assert "Traceback" not in gs.err.read_text()
    _no_traceback(rig)
    logs = list((tmp_path / "logs").glob("*_live_png.mcap"))
    assert len(logs) == 1
    info = inspect_log(logs[0])
    assert info.status == "ok" and info.law == "png"
    # the ground's closest approach (50 Hz ticks, target moved on by its velocity) agrees, to
    # within what PX4's estimate is off: the ground sees the SITL's reported position, which
    # carries the estimate model's error (sigma 0.05 m per axis; 3 sigma across the pass)
    sigma = load_scenario("cv-top-to-bottom").estimate.pos_noise_m
    assert abs(info.miss_m - result["miss_m"]) < 0.1 + 3 * math.sqrt(2) * sigma, (
        info.miss_m,
        result,
    )
    topics = {}
    for topic, _, _ in iter_messages(logs[0]):
        topics[topic] = topics.get(topic, 0) + 1
    assert topics["/control"] > 100 and topics["/world/target"] > 20, topics
    # loop timing (rate, jitter, overruns) is a benchmark figure (`groundstation bench --sitl`),
    # not asserted here: a shared 2-core machine cannot promise it; the loop must not stall
    assert stats["ticks"] > 0 and stats["rate_hz"] >= 100.0, stats
    # each setpoint's send is timed within its tick: every tick that sent one is a flying tick
    # and no other (on loopback no send is refused: each one counted as sent)
    fly = stats["flying_ticks"]
    assert fly == stats["commands_sent"], stats
    assert fly < stats["ticks"], stats  # those before the start sent none
    assert 0.0 < stats["setpoint_send_median_ms"] <= stats["setpoint_send_p99_ms"], stats
    assert 0.0 < stats["slowest_1pc_send_mean_ms"] < stats["slowest_1pc_work_mean_ms"], stats
    assert stats["detections_fused"] > 0, stats


# ---------------------------------------------------------------------- faults
def test_sitl_killed_mid_sortie_stops_every_command(rig_factory):
    rig = rig_factory(sitl_listens=True)
    rig.wait_ready()
    assert rig.start() == mavlink.MAV_RESULT_ACCEPTED
    rig.wait_text("offboard: intercepting")
    rig.pump(0.5)
    rig._killed = rig.sitl
    rig.sitl.kill()
    rig.sitl.wait(5)
    killed_at = time.monotonic()
    # take the dead vehicle's port and listen: no setpoint may arrive any more
    time.sleep(0.05)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", rig.fc_port))
    sock.settimeout(0.05)
    lost_at = rig.wait_text("FC link lost", timeout_s=5.0)
    assert lost_at - killed_at < 1.5
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    kinds = []
    end = time.monotonic() + 1.5
    while time.monotonic() < end:
        try:
            data = sock.recv(65535)
        except TimeoutError:
            continue
        if time.monotonic() - lost_at > 0.1:
            kinds += [m.get_type() for m in (mav.parse_buffer(data) or [])]
    sock.close()
    assert "SET_ATTITUDE_TARGET" not in kinds, kinds
    assert "HEARTBEAT" in kinds  # still alive, still talking
    rig.pump(0.3)
    assert rig.onboard.poll() is None
    assert rig.telemetry[-1]["state"] == 7  # link_lost
    _no_traceback(rig)


def test_detections_stopped_brake_and_hold_within_the_timeout(tmp_path, rig_factory):
    # a short ladder: coast 0.3 s, re-acquire 0.4 s, search 0.5 s after TGT_LOST_S (0.5 s)
    (tmp_path / "params.toml").write_text(
        "PRG_T_COAST = 0.3\nPRG_T_REACQ = 0.4\nPRG_T_SEARCH = 0.5\n"
    )
    rig = rig_factory(sitl_args=("--camera-blackout-after", "1.0"))
    rig.wait_ready()
    assert rig.start() == mavlink.MAV_RESULT_ACCEPTED
    lost_at = rig.wait_text("target lost: braking", timeout_s=10.0)
    rig.pump(0.2)
    tel_at_loss = [t for t in rig.telemetry if t["state"] == 5]  # braking
    assert tel_at_loss, "no braking telemetry"
    first = tel_at_loss[0]
    # the loop flew its ladder while intercepting: coast, reacquire, search (codes 4, 5, 6)
    modes = {t["loop_mode"] for t in rig.telemetry if t["state"] == 4}
    assert {4, 5, 6} <= modes, modes
    # The loop brakes 1.2 s (the ladder) after the last tick whose track was live, i.e. whose
    # DKF had fused a detection within 0.5 s (TGT_LOST_S): 1.7 s after that detection's
    # capture, give or take the tick intervals that straddle the loss and the search's start
    # (5 ms each; 50 ms allowed in all for a loaded machine). Telemetry samples the loop
    # every 20 ms, later under load, so the rows on either side of the brake bound it,
    # whatever their sampling delay: the last row before it, and the first braking row.
    # Both read the DKF's own time since the detection (the ticks' clock; telemetry's floats
    # are 32-bit).
    before = rig.telemetry[rig.telemetry.index(first) - 1]
    seen = [(r["t_s"], r["state"], r["loop_mode"], r["dkf_since_det_s"]) for r in (before, first)]
    anchor = before["t_s"] - before["dkf_since_det_s"]  # that detection's capture time
    assert before["t_s"] - anchor < 1.7 + 0.05, seen
    assert first["t_s"] - anchor >= 1.7 - 0.05, seen
    # it counts from the last detection the camera delivered, its stamp moved by the in-flight
    # camera-offset estimate (self-calibration; telemetry's floats are 32-bit, and the
    # estimate may move by a fraction of a millisecond after that detection)
    moved = first["raw_capture_t_s"] - first["selfcal_offset_s"]
    assert abs(moved - anchor) < 2e-3, (anchor, first)
    coasting = [t for t in rig.telemetry if t["state"] == 4 and t["loop_mode"] == 4]
    speeds = [np.hypot(t["vel_e_m_s"], t["vel_n_m_s"]) for t in coasting]
    assert max(speeds) > 1.0  # it was flying when the camera went dark, and coasted on
    rig.wait_text("finished (target lost): PX4 holds", timeout_s=15.0)
    rig.pump(0.3)
    last = rig.telemetry[-1]
    assert np.linalg.norm([last["vel_e_m_s"], last["vel_n_m_s"], last["vel_u_m_s"]]) < 0.5
    assert lost_at > 0
    _no_traceback(rig)


def test_a_start_before_the_target_is_seen_is_refused(tmp_path, rig_factory):
    scenario = tmp_path / "behind.toml"
    scenario.write_text(
        'name = "target-behind"\nduration_s = 20\n[interceptor]\nposition_m = [0.0, 0.0, 10.0]\n'
        'yaw_deg = 90.0\n[target]\nmotion = "static"\nposition_m = [0.0, -15.0, 10.0]\n'
    )
    rig = rig_factory(scenario=str(scenario))
    rig.wait_text("FC link up")
    rig.pump(1.0)
    assert rig.start() == mavlink.MAV_RESULT_DENIED
    rig.wait_text("start refused: no target in view")
    rig.pump(1.0)
    assert all(t["state"] == 1 for t in rig.telemetry[-20:])  # still waiting for a target
    assert all(t["commands_sent"] == 0 for t in rig.telemetry)
    assert "OFFBOARD" not in rig.sitl_out.read_text()
    _no_traceback(rig)


@pytest.mark.parametrize("sitl_listens", [True, False], ids=["sitl-listens", "onboard-listens"])
def test_garbage_on_every_port_and_an_out_of_range_param(rig_factory, sitl_listens):
    """Every listening port gets random datagrams and well-formed frames full of nonsense
    (NaN modes and setpoints, out-of-range thrust, unknown commands) during the pass: the
    flight controller's port is the SITL's or the onboard's depending on the topology."""
    rig = rig_factory(sitl_listens=sitl_listens, onboard_gcs_listens=True)
    rig.wait_ready()
    assert rig.param_set("PRG_V_MAX", 99.0) == 12.0  # refused: the unchanged value comes back
    assert rig.param_set("PRG_K_A", float("nan")) == 2.0
    assert rig.param_set("PRG_V_MAX", 10.0) == 10.0
    rng = np.random.default_rng(7)
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    nonsense = [
        mav.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, float("nan"), 0, 0, 0, 0,
                                0).pack(mav),
        mav.set_attitude_target_encode(0, 1, 1, 128, (1, 0, 0, 0), float("nan"), 0, 0,
                                       float("inf")).pack(mav),
        mav.set_attitude_target_encode(0, 1, 1, 128, (1, 0, 0, 0), 0, 0, 0, 7.0).pack(mav),
        mav.param_request_read_encode(1, 191, b"x", 10_000).pack(mav),
        mav.command_long_encode(1, 191, 31999, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav),
    ]  # fmt: skip
    assert rig.start() == mavlink.MAV_RESULT_ACCEPTED
    rig.wait_text("offboard: intercepting")
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for _ in range(200):
        blob = rng.bytes(int(rng.integers(1, 400)))
        for port in (rig.fc_port, rig.gcs_port):
            udp.sendto(blob, ("127.0.0.1", port))
            udp.sendto(nonsense[int(rng.integers(len(nonsense)))], ("127.0.0.1", port))
        rig.pump(0.005)
    udp.close()
    for _ in range(3):  # the camera port: connect, send junk, hang up
        with socket.create_connection(("127.0.0.1", rig.cam_port), timeout=2) as tcp:
            tcp.sendall(rng.bytes(5000))
    result = rig.sitl_result()
    _assert_hit(rig, result)
    if sitl_listens:
        # each distinct NaN / out-of-range setpoint is rejected; the same frame sent again is
        # dropped by the link as a duplicate before it gets that far
        assert result["rejected_setpoints"] >= 2
    rig.pump(0.5)
    rates = [t["loop_rate_hz"] for t in rig.telemetry if t["state"] == 4]
    steady = sorted(rates[len(rates) // 3 :])  # after the first second's window fills
    # the garbage must not stall the loop; exact rate and overrun figures are the benchmark's
    # (`groundstation bench --sitl`), not timed assertions on a shared machine
    assert steady and steady[len(steady) // 2] >= 100.0, rates
    stats = rig.close()
    assert stats["bad_frames_gcs"] >= 100, stats
    if not sitl_listens:
        assert stats["bad_frames_fc"] >= 100, stats
    _no_traceback(rig)


def test_abort_brakes_and_px4_rules_for_offboard(rig_factory):
    """The operator's abort brakes and hands over to PX4's Hold; the SITL vehicle refuses
    offboard without a setpoint stream and falls back to Hold when the stream stops."""
    from onboard.link.px4 import MavLink

    rig = rig_factory(sitl_listens=True)
    rig.wait_ready()
    intruder = MavLink(f"udpout:127.0.0.1:{rig.fc_port}", 255, 190)
    intruder.send(
        intruder.mav.command_long_encode(
            1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0, 0
        )
    )  # fmt: skip
    end = time.monotonic() + 3.0
    acks = []
    while time.monotonic() < end and not acks:
        acks = [m for m in intruder.poll() if m.get_type() == "COMMAND_ACK"]
        time.sleep(0.01)
    intruder.close()
    assert acks and acks[0].result == mavlink.MAV_RESULT_DENIED  # no setpoints: no offboard
    assert acks[0].target_system == 255 and acks[0].target_component == 190
    assert rig.start() == mavlink.MAV_RESULT_ACCEPTED
    rig.wait_text("offboard: intercepting")
    rig.pump(1.5)
    assert rig.abort() == mavlink.MAV_RESULT_ACCEPTED
    rig.wait_text("abort: braking and holding")
    rig.wait_text("finished (aborted by the operator): PX4 holds", timeout_s=15.0)
    rig.pump(0.3)
    last = rig.telemetry[-1]
    assert np.linalg.norm([last["vel_e_m_s"], last["vel_n_m_s"], last["vel_u_m_s"]]) < 0.5
    assert "SITL_RESULT" not in rig.sitl_out.read_text()  # aborted before the pass
    # a second sortie: start again, then the onboard process dies: PX4's offboard-loss
    # failsafe (1 s without a setpoint) puts the vehicle in Hold
    mark = len(rig.texts)
    assert rig.start() == mavlink.MAV_RESULT_ACCEPTED
    rig.wait_text("offboard: intercepting", after=mark)
    rig._killed = rig.onboard
    rig.onboard.kill()
    deadline = time.monotonic() + 4.0
    while "offboard loss" not in rig.sitl_out.read_text() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert "HOLD: offboard loss" in rig.sitl_out.read_text(), rig.logs()
    assert rig.sitl.poll() is None
