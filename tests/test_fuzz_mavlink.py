"""Every MAVLink link under hostile traffic: random bytes, truncated frames, frames with a bad
CRC, unknown message ids, duplicated and out-of-order copies of the real sender's frames, at
10x the link's normal input rate, on loopback. Each link keeps flying (its real traffic still
gets through and is acted on), counts what it dropped, and never sends a non-finite value.

The flood lasts PEREGRINE_FUZZ_FLOOD_S seconds (default 2 s to keep the suite fast; the full
run is 10 s: set PEREGRINE_FUZZ_FLOOD_S=10), at the full 10x rate either way."""

import io
import math
import os
import threading
import time
from collections import Counter

import numpy as np
import pytest

from onboard.link.px4 import (
    CMD_START,
    MODE_OFFBOARD,
    PX4_MAIN_OFFBOARD,
    MavLink,
    mavlink,
)

from .sitl_rig import free_port

FLOOD_S = float(os.environ.get("PEREGRINE_FUZZ_FLOOD_S", "2"))
# The flood and the link under test share this process (and the GIL) on a shared 2-core
# machine that can stall a process for a second or more, so these are liveness checks with
# wide margins, not speed targets: the link goes on receiving, acting and sending.
ALIVE = 0.05
_TALLY: Counter = Counter()


def _finite(msg) -> bool:
    """Every number in a message is finite (lists included)."""
    for v in msg.to_dict().values():
        for x in v if isinstance(v, (list, tuple)) else (v,):
            if isinstance(x, float) and not math.isfinite(x):
                return False
    return True


class Hostile:
    """Sends, from the real sender's own socket, a cycle of: random bytes, a truncated
    frame, a frame with a bad CRC, an unknown message id, a duplicate of the sender's last
    frame and an older one of its frames again (out of order)."""

    KINDS = ("random", "truncated", "bad_crc", "unknown_id", "duplicate", "out_of_order")

    def __init__(self, sender: MavLink, dest: tuple[str, int], seed: int) -> None:
        self.sock = sender.conn.port
        self.dest = dest
        self.rng = np.random.default_rng(seed)
        self.history: list[bytes] = []  # the real sender's frames, as sent
        self.sent: Counter = Counter()
        self._i = 0

    def frame(self) -> bytes:
        kind = self.KINDS[self._i % len(self.KINDS)]
        self._i += 1
        rng, hist = self.rng, self.history
        if kind in ("duplicate", "out_of_order", "truncated", "bad_crc") and len(hist) < 3:
            kind = "random"
        if kind == "random":
            data = rng.bytes(int(rng.integers(1, 280)))
        elif kind == "truncated":
            good = hist[-1]
            data = good[: int(rng.integers(1, len(good) - 1))]
        elif kind == "bad_crc":
            bad = bytearray(hist[-1])
            bad[-1 - int(rng.integers(0, 2))] ^= 0xFF
            data = bytes(bad)
        elif kind == "unknown_id":
            n = int(rng.integers(1, 40))
            header = bytes([0xFD, n, 0, 0, int(rng.integers(256)), 1, 1, 0xEF, 0xBE, 0xAD])
            data = header + rng.bytes(n + 2)
        elif kind == "duplicate":
            data = hist[-1]
        else:
            data = hist[-int(rng.integers(2, min(len(hist), 20) + 1))]
        self.sent[kind] += 1
        return data

    def send(self, n: int) -> None:
        for _ in range(n):
            try:
                self.sock.sendto(self.frame(), self.dest)
            except OSError:  # a full socket buffer under the flood: the kernel drops it
                self.sent["send_error"] += 1


def _real(sender: MavLink, hostile: Hostile, msg) -> None:
    """Send a real frame and remember its bytes for duplicates and reordering."""
    sender.send(msg)
    hostile.history.append(bytes(msg.get_msgbuf()))
    del hostile.history[:-50]


def _flood(seconds: float, rate_hz: float, hostile: Hostile, real_step, inbox=None) -> None:
    """``real_step(t)`` sends the real traffic due at t; the hostile frames go at rate_hz;
    ``inbox`` is ``(link, list)``: what the link receives meanwhile is appended."""
    t0 = time.perf_counter()
    done = 0
    while (t := time.perf_counter() - t0) < seconds:
        real_step(t)
        if inbox is not None:
            inbox[1].extend(inbox[0].poll(5000))
        due = int(t * rate_hz) - done
        if due > 0:
            hostile.send(due)
            done += due
        time.sleep(0.002)


def _report(fuzz_summary, link: str, hostile: Hostile, ok: bool) -> None:
    _TALLY["cases"] += sum(v for k, v in hostile.sent.items() if k != "send_error")
    _TALLY["failures"] += 0 if ok else 1
    fuzz_summary("MAVLink links (4 links, hostile frames)", _TALLY["cases"], _TALLY["failures"])


def _assert_counted(link: MavLink, hostile: Hostile) -> None:
    s = hostile.sent
    garbage = s["random"] + s["truncated"] + s["bad_crc"] + s["unknown_id"]
    assert link.bad_frames >= 0.5 * garbage, (link.bad_frames, dict(s))  # loopback may drop some
    assert link.duplicate_frames >= 0.5 * s["duplicate"], (link.duplicate_frames, dict(s))
    assert link.duplicate_frames + link.stale_frames >= 0.5 * (s["duplicate"] + s["out_of_order"])


# ----------------------------------------------------------------------------- SITL vehicle
def test_sitl_vehicle_keeps_flying_under_hostile_traffic(fuzz_summary):
    from groundstation.scenario import load_scenario
    from groundstation.sitl.camera_server import CameraServer
    from groundstation.sitl.vehicle import SitlOptions, SitlVehicle

    port = free_port()
    link = MavLink(f"udpin:127.0.0.1:{port}", 1, 1)
    camera = CameraServer("127.0.0.1", 0)
    options = SitlOptions(offboard_loss_s=5.0)  # a stalled test process is not a lost link
    vehicle = SitlVehicle(load_scenario("static-ahead-20m"), link, camera, options,
                          out=io.StringIO())  # fmt: skip
    onboard = MavLink(f"udpout:127.0.0.1:{port}", 1, 191)
    hostile = Hostile(onboard, ("127.0.0.1", port), seed=11)
    thread = threading.Thread(target=vehicle.run, args=(FLOOD_S + 1.5,), daemon=True)
    thread.start()
    hover = 1.0 / vehicle.scenario.interceptor.thrust_to_weight
    sent = {"n": 0}
    t_start = time.perf_counter()

    def setpoints(t: float) -> None:  # 200 Hz, as onboard run streams them
        while sent["n"] < t * 200:
            sent["n"] += 1
            now_ms = int((time.perf_counter() - t_start) * 1000) + 1
            _real(onboard, hostile, onboard.mav.set_attitude_target_encode(
                now_ms, 1, 1, mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE,
                (1.0, 0.0, 0.0, 0.0), 0.0, 0.0, 0.0, hover))  # fmt: skip

    try:
        out: list = []
        _flood(0.5, 0, hostile, setpoints, (onboard, out))  # streaming, then ask for offboard
        onboard.send(onboard.mav.command_long_encode(
            1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, PX4_MAIN_OFFBOARD, 0, 0, 0, 0, 0))  # fmt: skip
        _flood(FLOOD_S, 10 * 200, hostile, lambda t: setpoints(t + 0.5), (onboard, out))  # 10x
        thread.join(timeout=10)
        ok = vehicle.custom_mode == MODE_OFFBOARD
        ok = ok and vehicle.vehicle.finite() and all(_finite(m) for m in out)
        _report(fuzz_summary, "sitl", hostile, ok)
        assert vehicle.custom_mode == MODE_OFFBOARD  # setpoints kept arriving: no fallback
        assert vehicle.setpoints >= ALIVE * sent["n"] and vehicle.rejected_setpoints == 0
        assert vehicle.vehicle.finite() and vehicle.vehicle.p[2] > 5.0  # still up there
        kinds = Counter(m.get_type() for m in out)
        assert kinds["ATTITUDE_QUATERNION"] >= ALIVE * 200 * (FLOOD_S + 0.5) and all(
            _finite(m) for m in out
        )
        _assert_counted(link, hostile)
    finally:
        vehicle.stop()
        thread.join(timeout=5)
        camera.close()
        link.close()
        onboard.close()


# ----------------------------------------------------------------------------- onboard runtime
def _runtime(tmp_path):
    from onboard.runtime.runner import OnboardRuntime, RuntimeConfig

    fc_port, gcs_port = free_port(), free_port()
    fc = MavLink(f"udpin:127.0.0.1:{fc_port}", 1, 1)  # plays PX4
    gcs = MavLink(f"udpin:127.0.0.1:{gcs_port}", 255, 190)  # plays the ground station
    cfg = RuntimeConfig(
        fc_url=f"udpout:127.0.0.1:{fc_port}",
        camera="sitl://127.0.0.1:9",  # nothing there: the camera thread retries quietly
        gcs_url=f"udpout:127.0.0.1:{gcs_port}",
        params_path=tmp_path / "params.toml",
        realtime_priority=None,  # the test process's own threads
        lock_memory=False,
    )
    return OnboardRuntime(cfg, log=lambda _line: None), fc, gcs


def _px4_state(fc: MavLink, hostile: Hostile | None, t0: float):
    """PX4's stream at its normal rates: ATTITUDE_QUATERNION and HIGHRES_IMU 200 Hz,
    LOCAL_POSITION_NED 100 Hz, HEARTBEAT 1 Hz (500 frames/s)."""
    n = {"att": 0, "pos": 0, "hb": 0}

    def send(msg):
        if hostile is None:
            fc.send(msg)
        else:
            _real(fc, hostile, msg)

    def step(t: float) -> None:
        ms = int((time.perf_counter() - t0) * 1000) + 1
        while n["hb"] <= t:
            n["hb"] += 1
            send(fc.mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
                 mavlink.MAV_MODE_FLAG_SAFETY_ARMED | mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                 0x04030000, mavlink.MAV_STATE_ACTIVE))  # fmt: skip
        while n["att"] < t * 200:
            n["att"] += 1
            send(fc.mav.attitude_quaternion_encode(ms, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
            send(fc.mav.highres_imu_encode(ms * 1000, 0.0, 0.0, -9.81, 0.0, 0.0, 0.0,
                                           0, 0, 0, 0, 0, 0, 0, 0))  # fmt: skip
        while n["pos"] < t * 100:
            n["pos"] += 1
            send(fc.mav.local_position_ned_encode(ms, 0.0, 0.0, -10.0, 0.0, 0.0, 0.0))

    return step


def _run_runtime(rt, seconds):
    thread = threading.Thread(target=rt.run, args=(seconds,), daemon=True)
    thread.start()
    return thread


def _peer_address(link: MavLink, timeout_s: float = 3.0) -> tuple[str, int]:
    """The address the runtime sends from (its socket's port is chosen at its first send)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if link.poll():
            return next(iter(link.conn.clients))
        time.sleep(0.005)
    raise AssertionError("the runtime sent nothing")


def test_onboard_flight_controller_link_survives_hostile_traffic(tmp_path, fuzz_summary):
    rt, fc, gcs = _runtime(tmp_path)
    try:
        thread = _run_runtime(rt, FLOOD_S + 0.6)
        hostile = Hostile(fc, _peer_address(fc), seed=12)
        px4 = _px4_state(fc, hostile, time.perf_counter())
        out: list = []
        _flood(0.3, 0, hostile, px4, (fc, out))
        _flood(FLOOD_S, 10 * 500, hostile, lambda t: px4(t + 0.3), (fc, out))  # 10x PX4's 500/s
        thread.join(timeout=10)
        out += fc.poll(5000)
        stats = rt.stats()
        ok = all(_finite(m) for m in out)
        _report(fuzz_summary, "onboard-fc", hostile, ok)
        expected = (FLOOD_S + 0.6) * rt.config.control_rate_hz
        print(f"onboard loop under a PX4-link flood: {stats['rate_hz']:.1f} Hz")
        assert stats["ticks"] >= ALIVE * expected, stats  # the loop kept running
        assert rt.sm.state.value != "link_down", rt.sm.state  # PX4 still heard
        setpoints = [m for m in out if m.get_type() == "SET_ATTITUDE_TARGET"]
        assert all(_finite(m) for m in out), [m for m in out if not _finite(m)][:3]
        assert all(0.0 <= m.thrust <= 1.0 for m in setpoints)
        _assert_counted(rt.fc.link, hostile)
    finally:
        rt.camera.stop()
        for link in (fc, gcs, rt.fc.link, rt.ground.link):
            link.close()


def test_onboard_ground_link_survives_hostile_traffic(tmp_path, fuzz_summary):
    rt, fc, gcs = _runtime(tmp_path)
    thread = _run_runtime(rt, FLOOD_S + 0.6)
    hostile = Hostile(gcs, _peer_address(gcs), seed=13)
    px4 = _px4_state(fc, None, time.perf_counter())
    beats = {"n": 0}

    def ground(t: float) -> None:  # the ground's heartbeat at 1 Hz, PX4's stream as usual
        px4(t)
        while beats["n"] <= t:
            beats["n"] += 1
            _real(gcs, hostile, gcs.mav.heartbeat_encode(
                mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0))  # fmt: skip
        if beats["n"] == 2 and not beats.get("set"):
            beats["set"] = True
            _real(gcs, hostile, gcs.mav.param_set_encode(1, 191, b"PRG_K_BRAKE", 2.5, 9))

    try:
        # the onboard telemetry goes out at 25-50 Hz: 10x its rate back at it is 500 frames/s
        out: list = []
        sent_fc: list = []
        _flood(FLOOD_S + 0.3, 500, hostile, lambda t: (ground(t), sent_fc.extend(fc.poll(5000))),
               (gcs, out))  # fmt: skip
        thread.join(timeout=10)
        out += gcs.poll(5000)
        ok = rt.params.gains.k_brake == 2.5
        _report(fuzz_summary, "onboard-ground", hostile, ok)
        assert rt.params.gains.k_brake == 2.5  # the real PARAM_SET got through
        values = [m for m in out if m.get_type() == "PARAM_VALUE" and m.param_id == "PRG_K_BRAKE"]
        assert values and values[-1].param_value == 2.5
        telemetry = [m for m in out if m.get_type() == "DEBUG_FLOAT_ARRAY"]
        assert len(telemetry) >= 5 * FLOOD_S  # telemetry kept flowing
        assert rt.stats()["ticks"] >= ALIVE * (FLOOD_S + 0.6) * rt.config.control_rate_hz
        assert all(
            _finite(m) for m in sent_fc + fc.poll(5000)
        )  # nothing non-finite to the flight controller
        _assert_counted(rt.ground.link, hostile)
    finally:
        rt.camera.stop()
        for link in (fc, gcs, rt.fc.link, rt.ground.link):
            link.close()


# ----------------------------------------------------------------------------- dashboard live
def test_dashboard_live_link_survives_hostile_traffic(fuzz_summary):
    from groundstation.app.live import LiveSession
    from onboard.link import telemetry as tm

    port = free_port()
    session = LiveSession(f"udpin:127.0.0.1:{port}")
    onboard = MavLink(f"udpout:127.0.0.1:{port}", 1, 191)
    hostile = Hostile(onboard, ("127.0.0.1", port), seed=14)
    n = {"tel": 0, "hb": 0}
    t0 = time.perf_counter()

    def telemetry(t: float) -> None:  # the onboard component's 50 Hz telemetry + heartbeat
        while n["hb"] <= t:
            n["hb"] += 1
            _real(onboard, hostile, onboard.mav.heartbeat_encode(
                mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 2, 3))  # fmt: skip
        while n["tel"] < t * 50:
            n["tel"] += 1
            ts = time.perf_counter() - t0
            vals = {"t_s": ts, "state": 2, "loop_mode": 1, "e_est_u_px": 3.0,
                    "e_est_v_px": -2.0, "pos_e_m": 0.0, "pos_n_m": ts, "pos_u_m": 10.0,
                    "vel_n_m_s": 1.0, "image_w_px": 640, "image_h_px": 480, "f_px": 320.0,
                    "loop_rate_hz": 200.0}  # fmt: skip
            data = [float(v) for v in tm.pack(vals)]
            _real(onboard, hostile, onboard.mav.debug_float_array_encode(
                int(ts * 1e6) + 1, b"PRG_CTRL", 1, data))  # fmt: skip

    try:
        _flood(0.3, 0, hostile, telemetry)
        _flood(FLOOD_S, 10 * 100, hostile, lambda t: telemetry(t + 0.3))  # 10x its 100 frames/s
        time.sleep(0.2)
        st = session.status()
        live = st["live"]
        ok = live["link"] == "up"
        _report(fuzz_summary, "live", hostile, ok)
        assert live["link"] == "up" and live["onboard_state"] is not None
        assert st["time_s"] == pytest.approx(time.perf_counter() - t0, abs=0.5)  # fresh data
        assert math.isfinite(st["loop_rate_hz"]) and st["loop_rate_hz"] == 200.0
        rates = session.vehicle.link.rates_hz()
        assert rates.get("DEBUG_FLOAT_ARRAY", 0) >= ALIVE * 50  # the real 50 Hz gets through
        _assert_counted(session.vehicle.link, hostile)
        assert all(_finite(m) for m in onboard.poll(5000))  # what the session sent
    finally:
        session.close()
        onboard.close()


def test_the_adapter_drops_duplicates_and_stale_frames_and_counts_them():
    port = free_port()
    rx = MavLink(f"udpin:127.0.0.1:{port}", 1, 191)
    tx = MavLink(f"udpout:127.0.0.1:{port}", 255, 190)
    try:
        frames = []
        for k in range(5):
            msg = tx.mav.attitude_quaternion_encode(1000 + 10 * k, 1, 0, 0, 0, 0, 0, 0)
            frames.append(msg.pack(tx.mav))
        cmd = tx.mav.command_long_encode(1, 191, CMD_START, 0, 0, 0, 0, 0, 0, 0, 0).pack(tx.mav)
        for f in (frames[0], frames[1], frames[1], frames[3], frames[2], frames[4], cmd, cmd):
            tx.conn.port.sendto(f, ("127.0.0.1", port))
        time.sleep(0.1)
        got = rx.poll()
        stamps = [m.time_boot_ms for m in got if m.get_type() == "ATTITUDE_QUATERNION"]
        assert stamps == [1000, 1010, 1030, 1040]  # the duplicate and the late one dropped
        assert sum(m.get_type() == "COMMAND_LONG" for m in got) == 1
        assert (rx.duplicate_frames, rx.stale_frames) == (2, 1)
        restart = tx.mav.attitude_quaternion_encode(5, 1, 0, 0, 0, 0, 0, 0).pack(tx.mav)
        tx.conn.port.sendto(restart, ("127.0.0.1", port))  # a sender restarted: time from 0
        time.sleep(0.05)
        assert [m.time_boot_ms for m in rx.poll()] == [5]
    finally:
        rx.close()
        tx.close()
