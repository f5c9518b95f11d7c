"""The ground station's live mode in-process, against a fake onboard component."""

import math
import socket
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

from groundstation.app.live import LiveSession
from groundstation.app.server import GroundStation
from groundstation.app.session import SessionError
from onboard.gains import GAIN_NAMES, Gains
from onboard.link import telemetry as tm
from onboard.link.params import PARAM_IDS
from onboard.link.px4 import MavLink, mavlink

from .sitl_rig import free_port


def _wait(pred, timeout_s=3.0):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.02)
    return False


def _telemetry(onboard: MavLink, t: float, **extra) -> None:
    vals = {"t_s": t, "state": 2, "loop_mode": 1, "e_est_u_px": 3.0, "e_est_v_px": -2.0,
            "pos_e_m": 0.0, "pos_n_m": 1.0, "pos_u_m": 10.0, "vel_e_m_s": 0.0,
            "vel_n_m_s": 2.0, "vel_u_m_s": 0.0, "image_w_px": 640, "image_h_px": 480,
            "f_px": 320.0, "loop_rate_hz": 200.0}  # fmt: skip
    vals.update(extra)
    data = [float(v) for v in tm.pack({k: v for k, v in vals.items() if k in tm.INDEX})]
    for k, v in extra.items():
        if k.startswith("raw_"):
            data[int(k[4:])] = v
    onboard.send(onboard.mav.debug_float_array_encode(int(t * 1e6), b"PRG_CTRL", 1, data))


def test_live_session_reads_telemetry_and_survives_garbage_and_nonsense():
    port = free_port()
    session = LiveSession(f"udpin:127.0.0.1:{port}")
    onboard = MavLink(f"udpout:127.0.0.1:{port}", 1, 191)
    fc = MavLink(f"udpout:127.0.0.1:{port}", 1, 1)
    try:
        onboard.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 2, 3)
        _telemetry(onboard, 1.0)
        fc.send(fc.mav.local_position_ned_encode(0, 1.0, 0.0, -10.0, 2.0, 0.0, 0.0))
        assert _wait(lambda: session.status()["live"]["link"] == "up")
        assert _wait(lambda: session.vehicle.vehicle_p is not None)
        assert np.allclose(session.vehicle.vehicle_p, [0.0, 1.0, 10.0])  # NED -> ENU
        junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        rng = np.random.default_rng(5)
        for _ in range(100):
            junk.sendto(rng.bytes(int(rng.integers(1, 300))), ("127.0.0.1", port))
        junk.close()
        _telemetry(onboard, 1.1, loop_mode=57, state=-3, f_px=math.nan, image_w_px=1e12)
        onboard.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 999, 3)
        onboard.send(onboard.mav.param_value_encode(b"PRG_K_A", math.nan, 9, 22, 0))
        onboard.send(onboard.mav.param_value_encode(b"evil", 1.0, 9, 22, 0))
        onboard.send(onboard.mav.param_value_encode(b"PRG_K_A", 50.0, 9, 22, 0))  # out of range
        fc.send(fc.mav.local_position_ned_encode(0, math.nan, 0, 0, 0, 0, 0))
        time.sleep(0.3)
        st = session.status()
        snap = session.snapshot()
        assert st["live"]["bad_frames"] >= 100 and st["live"]["errors"] == 0
        assert snap["mode"] == "waiting" and snap["image"]["w"] == 640
        assert session.gains.k_a == 2.0 and "evil" not in session.vehicle.params
        assert np.allclose(session.vehicle.vehicle_p, [0.0, 1.0, 10.0])  # the NaN position ignored
        _telemetry(onboard, 1.2)
        assert _wait(lambda: session.snapshot().get("t") == 1.2)
        with pytest.raises(SessionError, match="live mode"):
            session.pause()
    finally:
        session.close()
        onboard.close()
        fc.close()


def test_gain_edits_wait_for_the_vehicles_param_value():
    port = free_port()
    session = LiveSession(f"udpin:127.0.0.1:{port}")
    onboard = MavLink(f"udpout:127.0.0.1:{port}", 1, 191)
    try:
        with pytest.raises(SessionError, match="no link"):
            session.set_gains(session.gains.replace(k_a=3.0))
        onboard.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 2, 3)
        assert _wait(lambda: session.vehicle.link_up())
        with pytest.raises(SessionError, match="not read yet"):
            session.set_gains(session.gains.replace(k_a=3.0))
        for i, (name, value) in enumerate(Gains().to_dict().items()):
            pid = PARAM_IDS[name].encode()
            onboard.send(onboard.mav.param_value_encode(pid, value, 9, 22, i))
        assert _wait(lambda: len(session.vehicle.params) == len(GAIN_NAMES))
        session.set_gains(session.gains.replace(k_a=3.0))
        sets = []

        def got_param_set():
            sets.extend(m for m in onboard.poll() if m.get_type() == "PARAM_SET")
            return bool(sets)

        assert _wait(got_param_set)
        assert sets[0].param_id == "PRG_K_A" and sets[0].param_value == 3.0
        st = session.status()
        assert st["gains_pending"] and st["live"]["params_pending"] == {"k_a": 3.0}
        assert session.gains.k_a == 2.0  # not applied until the vehicle says so
        onboard.send(onboard.mav.param_value_encode(b"PRG_K_A", 2.0, 9, 22, 0))  # refused
        assert _wait(lambda: not session.status()["gains_pending"])
        assert session.status()["live"]["params_refused"] == {"k_a": "k_a: vehicle kept 2"}
        session.set_gains(session.gains.replace(k_a=3.0))
        onboard.send(onboard.mav.param_value_encode(b"PRG_K_A", 3.0, 9, 22, 0))
        assert _wait(lambda: session.gains.k_a == 3.0 and not session.status()["gains_pending"])
    finally:
        session.close()
        onboard.close()


def test_live_routes_in_simulator_mode_are_refused(tmp_path):
    gs = GroundStation(port=0, data_dir=tmp_path, log_dir=tmp_path / "logs")
    try:
        with TestClient(gs.app, base_url="http://127.0.0.1") as c:
            assert c.post("/api/live/start").status_code == 401  # the token first
            c.headers["Authorization"] = f"Bearer {gs.token}"
            r = c.post("/api/live/start")
            assert r.status_code == 409 and "simulator mode" in r.json()["detail"]
    finally:
        gs.close()


def test_live_start_without_onboard_is_a_clear_error(tmp_path):
    gs = GroundStation(port=0, data_dir=tmp_path, log_dir=tmp_path / "logs",
                       mavlink_url=f"udpin:127.0.0.1:{free_port()}")  # fmt: skip
    try:
        with TestClient(gs.app, base_url="http://127.0.0.1") as c:
            c.headers["Authorization"] = f"Bearer {gs.token}"
            r = c.post("/api/live/abort")
            assert r.status_code == 409 and "no link" in r.json()["detail"]
            r = c.post("/api/sortie/start", json={"scenario": "cv-top-to-bottom"})
            assert r.status_code == 409 and "live mode" in r.json()["detail"]
            assert c.get("/api/status").json()["live"]["link"] == "never heard"
    finally:
        gs.close()


def test_a_signing_key_mismatch_is_named_when_a_command_goes_unanswered():
    import os

    port = free_port()
    session = LiveSession(f"udpin:127.0.0.1:{port}", signing_key=os.urandom(32))
    onboard = MavLink(
        f"udpout:127.0.0.1:{port}", 1, 191, os.urandom(32),
        unsigned_ok=(mavlink.MAVLINK_MSG_ID_HEARTBEAT,),
    )  # fmt: skip
    try:
        onboard.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 2, 3)
        assert _wait(lambda: session.vehicle.link_up())
        with pytest.raises(SessionError, match="signing key"):
            session.live_abort()
        assert _wait(lambda: onboard.poll() == [] and onboard.bad_frames >= 1)
    finally:
        session.close()
        onboard.close()


def test_an_unanswered_gain_edit_is_sent_again_then_reported(monkeypatch):
    """The parameter protocol's retry: a PARAM_SET lost on the way (or its PARAM_VALUE) is
    sent again after the timeout; one never answered is reported, not left waiting."""
    import groundstation.app.live as live

    monkeypatch.setattr(live, "PARAM_SET_TIMEOUT_S", 0.3)
    port = free_port()
    session = LiveSession(f"udpin:127.0.0.1:{port}")
    onboard = MavLink(f"udpout:127.0.0.1:{port}", 1, 191)
    try:
        onboard.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 2, 3)
        for i, (name, value) in enumerate(Gains().to_dict().items()):
            onboard.send(onboard.mav.param_value_encode(PARAM_IDS[name].encode(), value, 9, 22, i))
        assert _wait(lambda: len(session.vehicle.params) == len(GAIN_NAMES))
        sets = []

        def param_sets(n):
            def got():
                sets.extend(m for m in onboard.poll() if m.get_type() == "PARAM_SET")
                return len(sets) >= n

            return got

        # the first PARAM_SET is "lost" (not answered): the second is, and the edit applies
        session.set_gains(session.gains.replace(k_a=3.0))
        assert _wait(param_sets(2), 3.0)
        assert session.status()["live"]["params_sends"]["k_a"] >= 2  # shown while it waits
        assert session.gains.k_a == 2.0
        onboard.send(onboard.mav.param_value_encode(b"PRG_K_A", 3.0, 9, 22, 0))
        assert _wait(lambda: session.gains.k_a == 3.0 and not session.status()["gains_pending"])
        time.sleep(3 * live.PARAM_SET_TIMEOUT_S)  # answered: nothing more goes out
        param_sets(0)()
        assert {(m.param_id, m.param_value) for m in sets} == {("PRG_K_A", 3.0)}
        assert session.param_set_resends == len(sets) - 1 >= 1
        n = len(sets)
        time.sleep(3 * live.PARAM_SET_TIMEOUT_S)
        assert not param_sets(n + 1)()
        sets.clear()

        # never answered: sent PARAM_SET_SENDS times in all, then reported
        onboard.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 2, 3)
        session.set_gains(session.gains.replace(k_a=4.0))
        assert _wait(lambda: not session.status()["gains_pending"], 5.0)
        param_sets(live.PARAM_SET_SENDS)()
        assert len(sets) == live.PARAM_SET_SENDS == 4
        assert {(m.param_id, m.param_value) for m in sets} == {("PRG_K_A", 4.0)}
        assert session.status()["live"]["params_refused"] == {
            "k_a": "k_a: no PARAM_VALUE from the vehicle after 4 sends"
        }
        assert session.gains.k_a == 3.0  # what the vehicle last said it flies
    finally:
        session.close()
        onboard.close()


def test_a_lost_command_is_sent_again_with_its_confirmation_counting():
    """The command protocol's retry: the onboard never hears the first COMMAND_LONG (a radio
    fade), answers the second, and the operator's abort is accepted; the vehicle saw the
    confirmations 0 then 1. An onboard that answers none is reported after every send."""
    import threading

    port = free_port()
    session = LiveSession(f"udpin:127.0.0.1:{port}")
    onboard = MavLink(f"udpout:127.0.0.1:{port}", 1, 191, None)
    heard, answer, stop = [], [True], threading.Event()

    def vehicle():
        while not stop.is_set():
            onboard.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 2, 3)
            for m in onboard.poll():
                if m.get_type() == "COMMAND_LONG":
                    heard.append((m.command, m.confirmation))
                    if answer[0] and m.confirmation > 0:  # the first one was lost
                        ack = onboard.mav.command_ack_encode(m.command, 0, 0, 0, 255, 190)
                        onboard.send(ack)
            time.sleep(0.02)

    th = threading.Thread(target=vehicle, daemon=True)
    th.start()
    try:
        assert _wait(lambda: session.vehicle.link_up())
        assert session.live_abort()["result"] == "accepted"  # main: no acknowledgement
        assert heard == [(31011, 0), (31011, 1)]
        heard.clear()
        answer[0] = False
        with pytest.raises(SessionError, match=r"no acknowledgement .* after 3 sends"):
            session.live_abort()
        assert heard == [(31011, 0), (31011, 1), (31011, 2)]
    finally:
        stop.set()
        th.join()
        session.close()
        onboard.close()
