"""The onboard runtime in-process: the last-line output guard, loop overruns, the parameter
protocol and PX4's messages taken off the tick, against sockets this test reads."""

import itertools
import math
import os
import threading
import time

import numpy as np
import pytest

from onboard.link.params import PARAM_SPECS
from onboard.link.px4 import MavLink, mavlink
from onboard.runtime.runner import OnboardRuntime, RuntimeConfig

from .sitl_rig import free_port


def _runtime(tmp_path, **kw):
    fc_port, gcs_port = free_port(), free_port()
    fc = MavLink(f"udpin:127.0.0.1:{fc_port}", 1, 1)
    gcs = MavLink(f"udpin:127.0.0.1:{gcs_port}", 255, 190)
    kw = {"realtime_priority": None, "lock_memory": False, **kw}  # the test process's own
    cfg = RuntimeConfig(
        fc_url=f"udpout:127.0.0.1:{fc_port}",
        camera="sitl://127.0.0.1:9",  # nothing there: the camera thread retries quietly
        gcs_url=f"udpout:127.0.0.1:{gcs_port}",
        params_path=tmp_path / "params.toml",
        **kw,
    )
    lines: list[str] = []
    return OnboardRuntime(cfg, log=lines.append), fc, gcs, lines


def _collect(link: MavLink, kind: str, seconds: float = 1.0) -> list:
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        out += [m for m in link.poll() if m.get_type() == kind]
        time.sleep(0.005)
    return out


def test_a_non_finite_command_never_reaches_px4(tmp_path):
    rt, fc, gcs, lines = _runtime(tmp_path)
    try:
        rt.fc.send_command(np.array([math.nan, 0.0, 0.0]), 0.5, 1.0)
        rt.fc.send_command(np.array([0.1, 0.2, 0.3]), 1.7, 1.01)  # thrust out of range
        rt.fc.send_command(np.array([0.1, -0.2, 0.3]), 0.4, 1.02)
        rt._flush_events()
        sent = _collect(fc, "SET_ATTITUDE_TARGET", 0.5)
        assert len(sent) == 3
        for m in sent[:2]:
            assert (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate) == (0.0, 0.0, 0.0)
            assert m.thrust == np.float32(rt.params.runtime.HOVER_THR)
        ok = sent[2]  # FLU (0.1, -0.2, 0.3) -> FRD (0.1, 0.2, -0.3)
        assert np.allclose([ok.body_roll_rate, ok.body_pitch_rate, ok.body_yaw_rate],
                           [0.1, 0.2, -0.3], atol=1e-6)  # fmt: skip
        assert ok.type_mask & mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
        assert sum("output guard" in line for line in lines) == 2
        texts = [m.text for m in _collect(gcs, "STATUSTEXT", 0.3)]
        assert any("output guard" in t for t in texts)
    finally:
        rt.camera.stop()
        for link in (fc, gcs, rt.fc.link, rt.ground.link):
            link.close()


def test_a_slow_tick_is_reported_as_an_overrun(tmp_path):
    rt, fc, gcs, lines = _runtime(tmp_path, control_rate_hz=100.0)
    tick = rt.tick
    slow = {"n": 0}

    def slow_tick():
        tick()
        slow["n"] += 1
        if slow["n"] == 10:
            time.sleep(0.03)  # three periods

    rt.tick = slow_tick
    rt.run(duration_s=0.5)
    assert rt.overruns >= 1  # the slow tick (a loaded machine may add another)
    assert any("loop overrun" in line for line in lines)
    assert 40 <= rt.stats()["ticks"] <= 51  # 100 Hz for 0.5 s, less the stall
    for link in (fc, gcs):
        link.close()


def test_parameter_protocol_read_list_and_set(tmp_path):
    rt, fc, gcs, _ = _runtime(tmp_path)
    try:
        gcs.heartbeat(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        rt._heartbeats(0.0)
        time.sleep(0.05)
        gcs.poll()
        gcs.send(gcs.mav.param_request_list_encode(1, 191))
        gcs.send(gcs.mav.param_request_read_encode(1, 191, b"PRG_K_Z", -1))
        gcs.send(gcs.mav.param_request_read_encode(1, 191, b"", 2))
        gcs.send(gcs.mav.param_set_encode(1, 191, b"PRG_K_BRAKE", 2.5, 9))
        gcs.send(gcs.mav.param_set_encode(1, 191, b"PRG_CAM_HFOV", 500.0, 9))
        gcs.send(gcs.mav.param_set_encode(1, 42, b"PRG_K_BRAKE", 3.0, 9))  # not for us
        end = time.monotonic() + 1.0
        values = []
        while time.monotonic() < end:
            rt.tick()
            values += [m for m in gcs.poll() if m.get_type() == "PARAM_VALUE"]
            time.sleep(0.005)
        total = values[0].param_count
        assert total == len(PARAM_SPECS) and {m.param_index for m in values} == set(range(total))
        assert sum(m.param_id == "PRG_K_Z" for m in values) == 3  # list, read by name, by index
        brake = [m.param_value for m in values if m.param_id == "PRG_K_BRAKE"]
        assert brake[-1] == 2.5 and rt.params.gains.k_brake == 2.5
        hfov = [m.param_value for m in values if m.param_id == "PRG_CAM_HFOV"]
        assert hfov[-1] == 90.0  # out of range: the unchanged value comes back
        assert "PRG_K_BRAKE = 2.5" in (tmp_path / "params.toml").read_text()
    finally:
        rt.camera.stop()
        for link in (fc, gcs, rt.fc.link, rt.ground.link):
            link.close()


def test_px4_messages_wait_for_the_loop_lock_and_are_taken_in_order(tmp_path):
    rt, fc, gcs, _ = _runtime(tmp_path)
    px4 = mavlink.MAVLink(None, 1, 1)

    def position(x_m: float):
        msg = px4.local_position_ned_encode(int(1000 * x_m), x_m, 0.0, 0.0, 0.0, 0.0, 0.0)
        msg.pack(px4)  # stamps the sender (system 1, the autopilot) as on the wire
        return msg

    def receive() -> None:  # the receiver thread, while a fusion holds the loop's lock
        rt._take_fc_batch([position(1.0)])
        rt._take_fc_batch([position(2.0)])

    try:
        with rt._loop_lock:
            t = threading.Thread(target=receive)
            t.start()
            t.join(0.2)
            assert t.is_alive() and rt.fc.state.pos_enu_m is None  # a tick sees none of it
        t.join(5.0)
        assert rt.fc.state.pos_enu_m[1] == 2.0  # both taken, in order (NED x = ENU y)
    finally:
        rt.camera.stop()
        for link in (fc, gcs, rt.fc.link, rt.ground.link):
            link.close()


def test_a_refused_real_time_setting_is_one_warning_line_and_the_loop_runs(
    tmp_path, monkeypatch, capsys
):
    """Without the permission for SCHED_FIFO and mlockall: one line on stderr naming both and
    how to grant them, and the loop runs at normal priority."""
    from onboard.runtime import realtime

    def refuse(*_args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(realtime.os, "sched_setscheduler", refuse)
    monkeypatch.setattr(realtime, "lock_memory", lambda: "Operation not permitted")
    rt, fc, gcs, _ = _runtime(tmp_path, realtime_priority=40, lock_memory=True)
    rt.run(duration_s=0.3)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("onboard: real-time: no SCHED_FIFO 40 (Operation not permitted);")
    assert "no mlockall (Operation not permitted)" in err[0]
    assert "LimitRTPRIO" in err[0] and "LimitMEMLOCK=infinity" in err[0]
    st = rt.stats()
    assert st["ticks"] > 10 and st["realtime_priority"] is None and st["memory_locked"] is False
    for link in (fc, gcs):
        link.close()


def test_granted_real_time_priority_holds_while_the_loop_runs_and_is_undone(tmp_path):
    """Where SCHED_FIFO is permitted: the control thread runs under it, the other threads do
    not, and the thread is put back afterwards."""
    if not hasattr(os, "SCHED_FIFO"):
        pytest.skip("no SCHED_FIFO here")
    from onboard.runtime.check_rt import fifo_permitted

    if fifo_permitted(10) is not None:
        pytest.skip("SCHED_FIFO not permitted here")
    before = os.sched_getscheduler(0)
    rt, fc, gcs, _ = _runtime(tmp_path, realtime_priority=10)
    seen = {}
    tick = rt.tick

    def looking():
        seen.setdefault("control", os.sched_getscheduler(0))
        seen.setdefault("camera", os.sched_getscheduler(rt.camera.native_id))
        tick()

    rt.tick = looking
    rt.run(duration_s=0.2)
    assert seen == {"control": os.SCHED_FIFO, "camera": before}
    assert os.sched_getscheduler(0) == before and rt.stats()["realtime_priority"] == 10
    for link in (fc, gcs):
        link.close()


def test_each_tick_is_told_how_long_its_command_is_held(tmp_path):
    """The hold handed to the loop runs from the tick's start to the next deadline plus the
    recent mean lateness of the wake-ups: with delayed wake-ups (injected here) it is on
    average the time the command was really held."""
    rt, fc, gcs, _ = _runtime(tmp_path, control_rate_hz=100.0, inject_delays_seed=3)
    period = 0.01
    seen = []
    tick = rt.tick

    def looking():
        now = time.monotonic()
        seen.append((now, rt._hold_s, rt.scheduler.next_deadline_s - now))
        tick()

    rt.tick = looking
    rt.run(duration_s=1.5)
    for link in (fc, gcs):
        link.close()
    assert len(seen) > 50
    assert all(left <= hold <= 2 * period for _, hold, left in seen), seen
    # each hold against the time to the next tick, stalls left out (the loop takes their
    # excess back when the tick after them comes): no bias beyond a tenth of a period
    errors = [
        hold - (t1 - t0)
        for (t0, hold, _), (t1, _, _) in itertools.pairwise(seen)
        if t1 - t0 < 2 * period
    ]
    assert len(errors) > 0.8 * len(seen)
    assert abs(sum(errors) / len(errors)) < 0.1 * period, sorted(errors)
    st = rt.stats()
    assert st["injected_stalls"] == 1 and st["injected_delay_s"] > 0.03  # 30 ms at 1 s
    assert st["late_ticks"] >= 1 and st["missed_deadlines"] >= 3


def test_arm_mode_and_stream_requests_leave_with_the_sender_after_the_tick(tmp_path):
    # none of them feeds the command: the tick hands them to the sender thread, which sends
    # them once the tick has handed over (Sender.flush), in the order the tick asked
    from onboard.runtime.state_machine import Decision, Output

    rt, fc, gcs, _ = _runtime(tmp_path)
    rt.sm.step = lambda _inputs: Decision(
        Output.NONE, request_arm=True, request_offboard=True, request_streams=True
    )
    rt.sender.start()
    try:
        rt.tick()
        assert _collect(fc, "COMMAND_LONG", 0.3) == []  # held during the tick
        rt.sender.flush()
        got = [(m.command, m.param1, m.param2) for m in _collect(fc, "COMMAND_LONG", 1.0)]
        interval = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
        assert [c for c, _, _ in got if c == interval] == [interval] * 3
        assert (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0) in got
        mode = (mavlink.MAV_CMD_DO_SET_MODE, float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED))
        assert [g[:2] for g in got if g[0] == mode[0]] == [mode]
        assert got[0][0] == interval  # the streams first, as the tick asked
        assert rt.fc.mode_requested  # the acknowledgement is matched on the control thread
    finally:
        rt.sender.stop()
        rt.camera.stop()
        for link in (fc, gcs, rt.fc.link, rt.ground.link):
            link.close()
