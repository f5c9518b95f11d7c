"""The onboard runtime in-process: the last-line output guard, loop overruns, the parameter
protocol and PX4's messages taken off the tick, against sockets this test reads."""

import math
import os
import re
import threading
import time
from functools import partial

import numpy as np
import pytest

from onboard.link.params import PARAM_SPECS
from onboard.link.px4 import MavLink, mavlink
from onboard.runtime import runner
from onboard.runtime.runner import OnboardRuntime, RuntimeConfig
from onboard.runtime.scheduler import BindingWatch, keep_off

from .sitl_rig import free_port


def _runtime(tmp_path, **kw):
    fc_port, gcs_port = free_port(), free_port()
    fc = MavLink(f"udpin:127.0.0.1:{fc_port}", 1, 1)
    gcs = MavLink(f"udpin:127.0.0.1:{gcs_port}", 255, 190)
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
        rt._send_command(np.array([math.nan, 0.0, 0.0]), 0.5, 1.0)
        rt._send_command(np.array([0.1, 0.2, 0.3]), 1.7, 1.01)  # thrust out of range
        rt._send_command(np.array([0.1, -0.2, 0.3]), 0.4, 1.02)
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
        for link in (fc, gcs, rt.fc, rt.gcs):
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
        for link in (fc, gcs, rt.fc, rt.gcs):
            link.close()


def test_px4_messages_that_find_the_loop_busy_wait_in_order_for_the_next_tick(tmp_path):
    rt, fc, gcs, _ = _runtime(tmp_path)
    px4 = mavlink.MAVLink(None, 1, 1)

    def position(x_m: float):
        msg = px4.local_position_ned_encode(int(1000 * x_m), x_m, 0.0, 0.0, 0.0, 0.0, 0.0)
        msg.pack(px4)  # stamps the sender (system 1, the autopilot) as on the wire
        return msg

    held, release = threading.Event(), threading.Event()

    def fusing() -> None:  # the camera thread holding the loop's lock
        with rt._loop_lock:
            held.set()
            release.wait(5.0)

    try:
        t = threading.Thread(target=fusing)
        t.start()
        held.wait(5.0)
        rt._take_fc_batch([position(1.0)])  # on the receiver thread, while the lock is held
        rt._take_fc_batch([position(2.0)])
        assert rt.fcs.pos_enu_m is None  # waiting, not dropped, not blocking the receiver
        release.set()
        t.join(5.0)
        rt.tick()
        assert rt.fcs.pos_enu_m[1] == 2.0  # both taken by the tick, in order (NED x = ENU y)
        rt._take_fc_batch([position(3.0)])  # the lock free: taken at once
        assert rt.fcs.pos_enu_m[1] == 3.0
    finally:
        release.set()
        rt.camera.stop()
        for link in (fc, gcs, rt.fc, rt.gcs):
            link.close()


def test_a_batch_that_would_hold_the_lock_at_the_wake_up_is_left_to_the_tick(tmp_path):
    """A receiver's batch taken under the loop's lock must be done before the control thread
    wakes (TAKE_BUDGET_S): closer to the wake-up it waits, in order, for the tick to take it
    at its start, rather than hold the lock the rehearsal and the tick need."""
    from onboard.runtime.runner import TAKE_BUDGET_S

    rt, fc, gcs, _ = _runtime(tmp_path)
    px4 = mavlink.MAVLink(None, 1, 1)

    def position(x_m: float):
        msg = px4.local_position_ned_encode(int(1000 * x_m), x_m, 0.0, 0.0, 0.0, 0.0, 0.0)
        msg.pack(px4)
        return msg

    sched = rt.scheduler
    wake_lead_s = sched.spin_s + sched.rehearse_lead_s
    try:
        sched._running = True  # as in run(), without its threads
        sched._next_s = time.perf_counter() + wake_lead_s + TAKE_BUDGET_S / 2  # wakes soon
        assert not sched.time_for(TAKE_BUDGET_S)
        rt._take_fc_batch([position(1.0)])
        rt._take_fc_batch([position(2.0)])
        assert rt.fcs.pos_enu_m is None  # waiting, not taken
        rt.tick()
        assert rt.fcs.pos_enu_m[1] == 2.0  # both taken by the tick, in order
        sched._next_s = time.perf_counter() + 1.0  # the wake-up far: taken at once
        assert sched.time_for(TAKE_BUDGET_S)
        rt._take_fc_batch([position(3.0)])
        assert rt.fcs.pos_enu_m[1] == 3.0
    finally:
        sched._running = False
        rt.camera.stop()
        for link in (fc, gcs, rt.fc, rt.gcs):
            link.close()


def _run_looking(tmp_path, look, duration_s: float, **kw):
    """Run a 100 Hz runtime for ``duration_s`` calling ``look(rt)`` on the control thread
    after each of its ticks; returns the runtime and its lines."""
    rt, fc, gcs, lines = _runtime(tmp_path, control_rate_hz=100.0, **kw)
    tick = rt.tick

    def tick_and_look():
        tick()
        look(rt)

    rt.tick = tick_and_look
    try:
        rt.run(duration_s=duration_s)
    finally:
        for link in (fc, gcs):
            link.close()
    return rt, lines


def _affinity_while_running(tmp_path, **kw) -> dict:
    """The control thread's CPUs and the runtime's other threads' (by name), seen in a tick,
    with the runtime's lines."""
    seen: dict = {}

    def look(rt):
        if "control" not in seen:
            seen["control"] = os.sched_getaffinity(0)
            threads = (rt._fc_rx, rt._gcs_rx, rt.sender, rt.camera)  # this runtime's own
            seen["others"] = {t.name: os.sched_getaffinity(t.native_id) for t in threads}

    rt, seen["lines"] = _run_looking(tmp_path, look, 0.3, **kw)
    seen["stats"] = rt.stats()
    return seen


_PLACEABLE = (
    hasattr(os, "sched_getaffinity")
    and os.path.isdir("/proc/self/task")
    and len(os.sched_getaffinity(0)) >= 2
    and keep_off(os.sched_getaffinity(0), -1) is None  # allowed here (no seccomp, cpuset)
)


@pytest.mark.skipif(not _PLACEABLE, reason="one CPU, or placement not allowed here")
def test_one_cpu_is_left_to_the_control_thread_and_given_back(tmp_path):
    cpus = os.sched_getaffinity(0)
    top = max(cpus)
    seen = _affinity_while_running(tmp_path)
    assert seen["control"] == {top}  # the control thread bound to it
    # the two links' receivers, the sender and the camera thread: every CPU but that one
    assert len(seen["others"]) == 4, seen["others"]
    assert all(c == cpus - {top} for c in seen["others"].values()), seen["others"]
    assert seen["stats"]["reserved_cpu"] == top
    assert seen["stats"]["control_thread_bound"] is True
    assert seen["stats"]["binding_escapes"] == 0
    assert os.sched_getaffinity(0) == cpus
    off = _affinity_while_running(tmp_path, reserve_cpu=False)
    assert off["stats"]["reserved_cpu"] is None
    assert all(c == cpus for c in off["others"].values())


@pytest.mark.skipif(not _PLACEABLE, reason="one CPU, or placement not allowed here")
def test_a_control_thread_kept_waiting_on_its_cpu_is_freed_then_bound_again(tmp_path, monkeypatch):
    # another program on the CPU left to it (here a run delay of half the time, made up): a
    # bound thread could not leave, so it is freed for a while, then bound again and looked at
    cpus = os.sched_getaffinity(0)
    top = max(cpus)
    monkeypatch.setattr(runner, "run_delay_s", lambda: 0.5 * time.perf_counter())
    monkeypatch.setattr(
        runner, "BindingWatch", partial(BindingWatch, check_every_s=0.05, unbound_for_s=0.15)
    )
    affinity: list[set[int]] = []

    def look(_rt):
        cpus_now = os.sched_getaffinity(0)
        if not affinity or affinity[-1] != cpus_now:
            affinity.append(cpus_now)

    rt, lines = _run_looking(tmp_path, look, 0.6)
    assert affinity[:4] == [{top}, cpus, {top}, cpus], affinity  # bound, freed, bound, freed
    stats = rt.stats()
    assert stats["binding_escapes"] >= 2
    assert stats["binding_wait_max_fraction"] == pytest.approx(0.5, abs=0.02)
    freed = [line for line in lines if "free to run on any CPU" in line]
    assert len(freed) == stats["binding_escapes"]
    assert re.search(rf"waited (49|50|51) % of the time for CPU {top} .*for 0.15 s", freed[0])
    assert freed[1].endswith("for 0.3 s")  # still there after it was bound again: twice as long
    assert os.sched_getaffinity(0) == cpus  # every thread given back its CPUs


@pytest.mark.skipif(not _PLACEABLE, reason="one CPU, or placement not allowed here")
def test_without_its_run_delay_to_watch_the_control_thread_is_not_bound(tmp_path, monkeypatch):
    cpus = os.sched_getaffinity(0)
    top = max(cpus)
    monkeypatch.setattr(runner, "run_delay_s", lambda: None)  # no /proc schedstat
    seen = _affinity_while_running(tmp_path)
    assert seen["control"] == cpus  # free: a bound thread could not leave another program
    assert all(c == cpus - {top} for c in seen["others"].values()), seen["others"]
    assert seen["stats"]["reserved_cpu"] == top
    assert seen["stats"]["control_thread_bound"] is False
    assert seen["stats"]["binding_escapes"] is None


@pytest.mark.skipif(not _PLACEABLE, reason="one CPU, or placement not allowed here")
def test_a_refused_binding_is_a_warning_and_puts_every_thread_back(tmp_path, monkeypatch):
    cpus = os.sched_getaffinity(0)
    top = max(cpus)
    real = os.sched_setaffinity

    def refuse_binding(pid, cpu_set):
        if pid == 0 and set(cpu_set) == {top}:
            raise PermissionError("test")
        real(pid, cpu_set)

    monkeypatch.setattr(os, "sched_setaffinity", refuse_binding)
    seen = _affinity_while_running(tmp_path)
    assert any("CPU placement refused (test)" in line for line in seen["lines"])
    assert seen["control"] == cpus
    assert all(c == cpus for c in seen["others"].values()), seen["others"]
    assert seen["stats"]["reserved_cpu"] is None
    assert seen["stats"]["control_thread_bound"] is None


@pytest.mark.skipif(not _PLACEABLE, reason="one CPU, or placement not allowed here")
def test_a_refused_reservation_is_a_warning_and_puts_the_threads_back(tmp_path, monkeypatch):
    cpus = os.sched_getaffinity(0)
    calls = []

    def refuse_the_first(cpu_set, except_id):
        calls.append(cpu_set)
        if len(calls) == 1:  # the reservation: half done, then refused
            os.sched_setaffinity(rt_threads[0], cpu_set)
            return "CPU placement refused (test): threads left where the system puts them"
        return keep_off(cpu_set, except_id)

    rt_threads: list[int] = []
    real_start = threading.Thread.start

    def start_and_note(self):
        real_start(self)
        rt_threads.append(self.native_id)

    monkeypatch.setattr(threading.Thread, "start", start_and_note)
    monkeypatch.setattr(runner, "keep_off", refuse_the_first)
    seen = _affinity_while_running(tmp_path)
    assert any("CPU placement refused" in line for line in seen["lines"])
    assert seen["stats"]["reserved_cpu"] is None
    assert seen["stats"]["control_thread_bound"] is None
    assert seen["control"] == cpus
    assert all(c == cpus for c in seen["others"].values()), seen["others"]


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
        assert rt._mode_requested  # the acknowledgement is matched on the control thread
    finally:
        rt.sender.stop()
        rt.camera.stop()
        for link in (fc, gcs, rt.fc, rt.gcs):
            link.close()


def test_a_tick_that_raised_on_the_camera_thread_ends_the_run_as_on_the_control_thread(tmp_path):
    """The early tick the camera thread ticks itself (scheduler.tick_here) fails as a control
    thread's tick fails: the run stops with its exception, rather than the camera thread
    counting it and carrying on."""
    rt, fc, gcs, _ = _runtime(tmp_path)
    here = threading.current_thread()  # this test plays the camera thread
    tick = rt.tick

    def tick_failing_here():
        if threading.current_thread() is here:
            raise RuntimeError("tick failed")
        tick()

    rt.tick = tick_failing_here
    errors: list[Exception] = []

    def run():
        try:
            rt.run(duration_s=5.0)
        except RuntimeError as exc:
            errors.append(exc)

    th = threading.Thread(target=run)
    th.start()
    try:
        start, end = None, time.monotonic() + 3.0
        while start is None and time.monotonic() < end:
            time.sleep(0.001)
            with rt._loop_lock:  # as _fuse_on_arrival, right after a fusion
                start = rt.scheduler.tick_here()  # None while the control thread is awake
                if start is not None:
                    rt._tick_here(start)
        assert start is not None
        th.join(3.0)
        assert not th.is_alive()
        assert [str(e) for e in errors] == ["tick failed"]
        assert rt.stats()["tick_work_by_kind"]["early tick on the camera thread"]["ticks"] == 1
    finally:
        rt.stop()
        th.join(3.0)
        for link in (fc, gcs):
            link.close()
