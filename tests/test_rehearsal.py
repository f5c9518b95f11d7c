"""The tick rehearsed before its deadline (onboard/runtime/rehearsal.py, #16 item 5): the shadow
loop shares nothing with the loop (the commands flown with rehearsals are those without, to the
bit), it is taken afresh when the loop's mode moves away from it or it is old, its failure is
counted and dropped, the frame it packs is the setpoint PX4 would get; the scheduler rehearses
before grid ticks only, inside the deadline, and keeps the other threads off it (fake clock:
no timing asserted)."""

from __future__ import annotations

import dataclasses
import math
import socket
import sys
import threading
import time

import numpy as np
import pytest

from groundstation.scenario import load_scenario
from groundstation.sim.simulation import Simulation
from onboard.datatypes import LoopMode, SharedWhenCopied
from onboard.link.px4 import mavlink
from onboard.loop import InterceptionLoop
from onboard.runtime.rehearsal import Rehearsal
from onboard.runtime.runner import REHEARSED_SEND_MIN_LEAD_S, OnboardRuntime, RuntimeConfig
from onboard.runtime.scheduler import PeriodicScheduler
from onboard.runtime.timing import LoopTiming

from .sitl_rig import free_port
from .test_runtime_early_tick import FakeClock, P, configs_of_onboard_run


def _fly(monkeypatch, scenario: str, rehearse: bool, seed: int = 3):
    """One simulated sortie; with ``rehearse`` every tick of its loop is preceded by a
    rehearsal on the shadow at the same state and followed by the runtime's refresh policy.
    Returns (commands as bytes, result, rehearsal)."""
    sim = Simulation(load_scenario(scenario), "png", seed, keep_records=False)
    real = sim.loop
    rh = Rehearsal(max_age_ticks=40)
    commands: list[bytes] = []
    plain_tick = InterceptionLoop.tick

    def tick(self, state, brake=False, hold_s=None):
        if self is not real:  # the shadow's own tick
            return plain_tick(self, state, brake, hold_s)
        if rehearse:
            rh.run(state, hold_s)
        tel = plain_tick(self, state, brake, hold_s)
        cmd = tel.command
        commands.append(
            cmd.body_rates_flu_rad_s.tobytes() + np.float64(cmd.thrust_normalised).tobytes()
        )
        if rehearse and rh.needs_refresh(self):
            rh.refresh(self)
        return tel

    monkeypatch.setattr(InterceptionLoop, "tick", tick)
    result = sim.run()
    monkeypatch.setattr(InterceptionLoop, "tick", plain_tick)
    return commands, result, rh


@pytest.mark.parametrize("scenario", ["cv-top-to-bottom", "indoor-tethered-wind-4"])
def test_rehearsals_leave_every_command_flown_unchanged_to_the_bit(monkeypatch, scenario):
    without, res0, _ = _fly(monkeypatch, scenario, rehearse=False)
    with_, res1, rh = _fly(monkeypatch, scenario, rehearse=True)
    print(f"{scenario}: {len(with_)} ticks, {rh.runs} rehearsals, {rh.refreshes} copies")
    assert rh.errors == 0
    assert rh.runs >= len(with_) - 1  # every tick but the first (no shadow yet)
    assert rh.refreshes >= 3  # the mode moved (search, tracking, ...) and age
    assert with_ == without
    assert res1 == res0  # the sortie's result (outcome, miss, time) likewise


def test_the_shadow_is_taken_afresh_when_the_mode_moves_or_it_is_old():
    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, keep_records=False)
    loop = sim.loop
    rh = Rehearsal(max_age_ticks=3)
    assert rh.needs_refresh(loop)  # none yet
    rh.refresh(loop)
    assert rh.shadow is not loop and rh.shadow.dkf is not loop.dkf
    assert [rh.needs_refresh(loop) for _ in range(4)] == [False, False, False, True]
    rh.refresh(loop)
    loop.mode = LoopMode.TRACKING if loop.mode is not LoopMode.TRACKING else LoopMode.COAST
    assert rh.needs_refresh(loop)
    assert rh.refreshes == 2


def test_the_shadow_shares_the_loops_immutable_values_and_none_of_its_state():
    """The gains, camera model, airframe and configurations are frozen values: the shadow
    reads the loop's own (so the rehearsal leaves them in the caches for the tick), while
    everything a tick changes is the shadow's (the to-the-bit test above flies it)."""
    import copy

    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, keep_records=False)
    loop = sim.loop
    rh = Rehearsal()
    rh.refresh(loop)
    sh = rh.shadow
    values = (loop.gains, loop.camera, loop.vehicle, loop.dkf.config, loop.disturbance.config)
    shared = (sh.gains, sh.camera, sh.vehicle, sh.dkf.config, sh.disturbance.config)
    assert all(a is b for a, b in zip(values, shared, strict=True))
    assert all(copy.copy(v) is v and copy.deepcopy(v) is v for v in values)
    # shared only if immutable: frozen, and every attribute a number, a string, a tuple of
    # them or a read-only array (the camera's mount rotation); every such class is here
    # (by name: a slots dataclass leaves the class it was made from among the subclasses)
    assert {c.__qualname__ for c in SharedWhenCopied.__subclasses__()} == {
        type(v).__qualname__ for v in values
    }

    def immutable(x) -> bool:
        if isinstance(x, tuple):
            return all(immutable(y) for y in x)
        if isinstance(x, np.ndarray):
            return not x.flags.writeable
        return isinstance(x, (int, float, str, type(None)))

    for v in values:
        assert type(v).__dataclass_params__.frozen, type(v)
        attrs = {f.name: getattr(v, f.name) for f in dataclasses.fields(v)}
        attrs.update(getattr(v, "__dict__", {}))
        assert all(immutable(x) for x in attrs.values()), (type(v), attrs)
    assert sh.dkf is not loop.dkf and sh.disturbance is not loop.disturbance
    assert sh.dkf._P is not loop.dkf._P and sh.dkf._X is not loop.dkf._X
    assert sh._R_hist is not loop._R_hist and sh._detections is not loop._detections


def test_a_replaced_shadow_is_freed_without_the_collector():
    """The runtime runs with automatic collection off (scheduler.py): a shadow in a reference
    cycle would pile up, one per copy (about one a second), until the next full collection."""
    import gc
    import weakref

    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, keep_records=False)
    rh = Rehearsal()
    rh.refresh(sim.loop)
    rh.run(_state(sim), 0.005)
    old = weakref.ref(rh.shadow)
    was = gc.isenabled()
    gc.disable()
    try:
        rh.refresh(sim.loop)
        assert old() is None
    finally:
        if was:
            gc.enable()


def _state(sim: Simulation):
    return sim.vehicle.state(0.01)


def test_a_failing_rehearsal_is_counted_and_its_shadow_dropped():
    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, keep_records=False)
    rh = Rehearsal()
    assert rh.run(_state(sim), None) is None and rh.runs == 0  # no shadow: nothing to run
    rh.refresh(sim.loop)

    def broken(*_a, **_k):
        raise FloatingPointError("a bad copy")

    rh.shadow.tick = broken
    assert rh.run(_state(sim), 0.005) is None
    assert rh.errors == 1 and rh.shadow is None and rh.needs_refresh(sim.loop)


def test_the_rehearsed_frame_is_the_setpoint_px4_would_get():
    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, keep_records=False)
    rh = Rehearsal()
    rh.refresh(sim.loop)
    state = _state(sim)
    frame = rh.run(state, 0.005)
    assert frame is not None
    # the shadow's own command, ticked again on a fresh copy: what the frame must carry
    twin = Rehearsal()
    twin.refresh(sim.loop)
    cmd = twin.shadow.tick(state, False, 0.005).command
    msg = mavlink.MAVLink(None).decode(bytearray(frame))
    assert msg.get_type() == "SET_ATTITUDE_TARGET"
    x, y, z = cmd.body_rates_flu_rad_s.tolist()
    assert (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate) == pytest.approx(
        (x, -y, -z), rel=1e-6, abs=1e-7
    )  # FLU -> FRD, float32 on the wire
    assert msg.thrust == pytest.approx(cmd.thrust_normalised, rel=1e-6)
    assert msg.type_mask == mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE


def test_a_refused_command_packs_no_frame():
    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, keep_records=False)
    rh = Rehearsal()
    rh.refresh(sim.loop)
    good = rh.shadow.tick

    def wild(*a, **k):
        tel = good(*a, **k)
        tel.command.body_rates_flu_rad_s[0] = math.nan
        return tel

    rh.shadow.tick = wild
    assert rh.run(_state(sim), 0.005) is None and rh.errors == 0


# ---------------------------------------------------------------------- the scheduler
LEAD = 0.0003


def _grid(clock: FakeClock, n: int, rehearse_work_s: float = 0.0001, requests=()):
    """n ticks on the fake clock with a rehearsal that works ``rehearse_work_s``; returns the
    tick starts, the rehearsals' (start, deadline) and the scheduler."""
    rehearsed: list[float] = []

    def rehearse() -> bool:
        rehearsed.append(clock.t)
        clock.work(rehearse_work_s)
        return True

    sched = PeriodicScheduler(
        P, clock=clock.now, block=clock.block, rehearse=rehearse, rehearse_lead_s=LEAD
    )
    for t in requests:
        clock.at(t, sched.request_tick)
    starts = []
    sched.start()
    try:
        for _ in range(n):
            starts.append((sched.wait(), sched.early))
            sched.served()
            clock.work(0.0001)
            sched.after_tick()
    finally:
        sched.stop()
    return starts, rehearsed, sched


def test_grid_ticks_are_rehearsed_inside_the_lead_and_still_start_on_time():
    clock = FakeClock()
    starts, rehearsed, sched = _grid(clock, 6)
    first = starts[0][0]
    # the first tick is due at once (no time to rehearse); each later one is rehearsed
    # within lead + spin before its deadline, and the tick starts at the deadline
    assert len(rehearsed) == 5
    assert sched.rehearsals_skipped == {
        "early tick": 0,
        "fusion": 0,
        "woken late": 1,
        "declined": 0,
    }
    for k, r in enumerate(rehearsed, start=1):
        deadline = first + k * P
        assert deadline - sched.spin_s - LEAD - 1e-5 <= r < deadline - sched.spin_s
        assert starts[k][0] == pytest.approx(deadline, abs=1e-5)
    assert len(sched.rehearsal_s) == 5
    assert all(s == pytest.approx(0.0001, abs=1e-5) for s in sched.rehearsal_s)
    # each sleep ended when asked (the fake clock's reading steps aside)
    assert len(sched.wake_overshoot_s) == 5
    assert all(0.0 <= o < 1e-5 for o in sched.wake_overshoot_s)


class OversleepingClock(FakeClock):
    """A fake clock whose sleeps end ``late_s`` after the time asked (a busy host)."""

    def __init__(self, late_s: float) -> None:
        super().__init__()
        self.late_s = late_s

    def block(self, timeout_s: float) -> None:
        super().block(timeout_s + self.late_s)


def test_a_wake_up_later_than_the_lead_is_measured_and_not_rehearsed():
    clock = OversleepingClock(late_s=0.0004)  # beyond the 0.3 ms lead
    starts, rehearsed, sched = _grid(clock, 4)
    assert rehearsed == []
    assert sched.rehearsals_skipped["woken late"] == 4
    assert len(sched.wake_overshoot_s) == 3  # the first tick did not sleep
    assert all(o == pytest.approx(0.0004, abs=1e-5) for o in sched.wake_overshoot_s)
    first = starts[0][0]
    # 0.4 ms late from a wake-up 0.6 ms early: still on time
    assert [s for s, _ in starts[1:]] == pytest.approx([first + k * P for k in (1, 2, 3)], abs=1e-5)


def test_an_early_tick_is_not_rehearsed():
    clock = FakeClock()
    starts, rehearsed, sched = _grid(clock, 5, requests=(100.0122,))
    assert [e for _, e in starts] == [False, False, False, True, False]
    early_start = starts[3][0]
    assert early_start == pytest.approx(100.0122, abs=1e-5)  # at once, no rehearsal first
    assert not any(early_start - 0.001 < r <= early_start for r in rehearsed)
    assert len(rehearsed) == 3  # the grid ticks after the first (the early one is not)
    assert sched.rehearsals_skipped == {
        "early tick": 1,
        "fusion": 0,
        "woken late": 1,
        "declined": 0,
    }


def test_each_tick_says_how_its_wake_up_went_and_its_work_is_kept_apart_by_it():
    clock = FakeClock()
    kinds = []
    ran = iter([True, False, True, True, True])  # the second rehearsal declines (no shadow yet)

    def rehearse() -> bool:
        clock.work(0.0001)
        return next(ran)

    sched = PeriodicScheduler(
        P, clock=clock.now, block=clock.block, rehearse=rehearse, rehearse_lead_s=LEAD
    )
    clock.at(100.0222, sched.request_tick)
    timing = LoopTiming(P, keep=100)
    sched.start()
    try:
        for _ in range(7):
            start = sched.wait()
            timing.tick_started(start, sched.early, sched.woken_as)
            kinds.append(sched.woken_as)
            sched.served()
            clock.work(0.0009 if sched.early else 0.0001)
            timing.tick_done(clock.t - start)
            sched.after_tick()
    finally:
        sched.stop()
    assert kinds == [
        "woken late", "rehearsed", "declined", "rehearsed", "rehearsed", "early tick", "rehearsed"
    ]  # fmt: skip
    assert sched.rehearsals_skipped == {
        "early tick": 1,
        "fusion": 0,
        "woken late": 1,
        "declined": 1,
    }
    by = timing.work_by_kind()
    assert {k: v["ticks"] for k, v in by.items()} == {
        "woken late": 1,
        "rehearsed": 4,
        "declined": 1,
        "early tick": 1,
    }
    # the slowest 1 % (here the slowest tick) is the early one
    assert by["early tick"]["in_slowest_1pc"] == 1
    assert sum(v["in_slowest_1pc"] for v in by.values()) == 1
    assert by["early tick"]["median_ms"] == pytest.approx(0.9, abs=0.01)
    assert by["rehearsed"]["p99_ms"] == pytest.approx(0.1, abs=0.01)
    assert timing.figures()["tick_work_by_kind"] == by


def test_a_rehearsal_that_runs_past_the_deadline_makes_the_tick_late_and_shows_it():
    clock = FakeClock()
    starts, _, sched = _grid(clock, 3, rehearse_work_s=0.001)
    first = starts[0][0]
    late = starts[1][0] - (first + P)
    assert late == pytest.approx(0.001 - sched.spin_s - LEAD, abs=2e-5)  # seen as jitter


def test_other_threads_are_kept_off_the_rehearsal_window():
    clock = FakeClock()
    sched = PeriodicScheduler(
        P, clock=clock.now, block=clock.block, rehearse=lambda: None, rehearse_lead_s=LEAD
    )
    sched.start()
    try:
        sched.wait()
        sched.after_tick()
        # the slack ends lead + spin before the next deadline, not spin before it
        nxt = sched._next_s
        assert sched.slack_s() == pytest.approx(nxt - sched.spin_s - LEAD - clock.t, abs=2e-6)
    finally:
        sched.stop()
    plain = PeriodicScheduler(P, clock=clock.now, block=clock.block, rehearse_lead_s=LEAD)
    assert plain.rehearse_lead_s == 0.0  # no rehearsal, no earlier wake-up


@pytest.mark.parametrize(("flag", "expected"), [(None, True), ("on", True), ("off", False)])
def test_onboard_run_rehearse_flag_reaches_the_runtime(monkeypatch, flag, expected):
    seen = configs_of_onboard_run(monkeypatch, [] if flag is None else ["--rehearse", flag])
    assert [c.rehearse for c in seen] == [expected]


# ---------------------------------------------------------------------- the runtime
def _runtime(tmp_path, rehearse: bool = True, fc_port: int | None = None):
    cfg = RuntimeConfig(
        fc_url=f"udpout:127.0.0.1:{fc_port or free_port()}",
        camera="sitl://127.0.0.1:9",  # never opened: run() is not called
        params_path=tmp_path / "params.toml",
        rehearse=rehearse,
    )
    rt = OnboardRuntime(cfg, log=lambda _s: None)
    rt._build_loop(640, 480)
    f = rt.fcs
    f.pos_enu_m, f.vel_enu_m_s = np.array([0.0, 0.0, 10.0]), np.array([0.5, 3.0, 0.2])
    f.q_wxyz, f.q_time_s = np.array([1.0, 0.0, 0.0, 0.0]), rt.clock.now()
    return rt


def test_the_runtime_copies_its_loop_only_with_slack_and_rehearses_with_the_lock(tmp_path):
    rt = _runtime(tmp_path)
    try:
        rh, sched = rt.rehearsal, rt.scheduler
        assert sched.rehearse == rt._rehearse and sched.rehearse_lead_s > 0.0
        sched._next_s = time.perf_counter()  # the next wake-up is due: no copy now
        rt._refresh_shadow()
        assert rh.shadow is None and rh.refreshes == 0
        sched._next_s = time.perf_counter() + 1.0
        rt._refresh_shadow()
        assert rh.shadow is not None and rh.shadow is not rt.loop and rh.refreshes == 1
        rt._rehearse()
        assert rh.runs == 1 and rh.errors == 0
        held = threading.Event()
        release = threading.Event()

        def hold_the_lock() -> None:
            with rt._loop_lock:  # another thread's batch, long
                held.set()
                release.wait(5.0)

        t = threading.Thread(target=hold_the_lock)
        t.start()
        held.wait(5.0)
        # waited for no longer than REHEARSAL_LOCK_WAIT_S (the holder lets go only after)
        assert rt._rehearse() is False
        release.set()
        t.join(5.0)
        assert rh.runs == 1
        stats = rt.stats()
        assert stats["rehearse"] is True and stats["rehearsals"] == 1
        assert stats["shadow_refreshes"] == 1 and stats["rehearsal_errors"] == 0
    finally:
        rt.fc.close()


def _hold_lock(rt, release: threading.Event, then_s: float = 0.0) -> threading.Thread:
    """Another thread's batch holding the loop's lock until ``release`` is set, then
    ``then_s`` more (s); returns once it holds it."""
    held = threading.Event()

    def batch() -> None:
        with rt._loop_lock:
            held.set()
            release.wait(5.0)
            time.sleep(then_s)

    t = threading.Thread(target=batch)
    t.start()
    held.wait(5.0)
    return t


def test_the_rehearsal_waits_for_a_batch_holding_the_lock_but_not_into_the_spin(
    tmp_path, monkeypatch
):
    """A receiver's batch that ran into the wake-up holds the loop's lock: the rehearsal waits
    for it asleep (the holder then ends its batch) and runs, rather than declining and leaving
    the tick to wait for the lock; never past the start of the spin to the deadline, and not
    when an input came meanwhile (its early tick goes first)."""
    import onboard.runtime.runner as runner

    rt = _runtime(tmp_path)
    try:
        rh, sched = rt.rehearsal, rt.scheduler
        sched._next_s = time.perf_counter() + 10.0
        rt._refresh_shadow()
        monkeypatch.setattr(runner, "REHEARSAL_LOCK_WAIT_S", 5.0)  # the spin bounds it below
        lock = rt._loop_lock
        release = threading.Event()

        class Telling:  # the loop's lock, letting the batch go when the rehearsal waits for it
            def acquire(self, blocking=True, timeout=-1):
                if blocking:
                    release.set()
                return lock.acquire(blocking, timeout)

            def release(self):
                lock.release()

        t = _hold_lock(rt, release, then_s=0.02)  # the rest of the batch, 20 ms
        rt._loop_lock = Telling()
        assert rt._rehearse() is True  # waited for the batch, then rehearsed
        t.join(5.0)
        assert rh.runs == 1
        stats = rt.stats()
        assert stats["rehearsal_lock_waits"] == 1 and stats["rehearsal_lock_wait_max_ms"] >= 15.0
        assert stats["rehearsals_declined_lock_held"] == 0
        rt._loop_lock = lock

        # the spin 0.1 s away: waited for that long at most, then declined (not into the spin)
        release.clear()
        t = _hold_lock(rt, release)
        sched._next_s = time.perf_counter() + sched.spin_s + 0.1
        asked = time.perf_counter()
        assert rt._rehearse() is False  # the holder lets go only after it returns
        waited = time.perf_counter() - asked
        release.set()
        t.join(5.0)
        assert 0.05 < waited < 2.0  # bounded by the spin, not the 5 s allowed
        assert rh.runs == 1 and rt.stats()["rehearsals_declined_lock_held"] == 1

        # spinning already: declined at once
        release.clear()
        t = _hold_lock(rt, release)
        sched._next_s = time.perf_counter() + sched.spin_s / 2
        assert rt._rehearse() is False  # the holder lets go only after it returns
        release.set()
        t.join(5.0)
        assert rh.runs == 1 and rt.stats()["rehearsals_declined_lock_held"] == 2

        # the lock got after a fusion began meanwhile: its early tick first, not a rehearsal
        sched._next_s = time.perf_counter() + 10.0
        release.clear()
        t = _hold_lock(rt, release, then_s=0.02)
        rt._loop_lock = Telling()
        sched.input_begins()
        try:
            assert rt._rehearse() is False
        finally:
            sched.input_done()
            rt._loop_lock = lock
        t.join(5.0)
        assert rh.runs == 1
        assert rt.stats()["rehearsals_declined_lock_held"] == 2  # not a batch's
    finally:
        rt.fc.close()


def test_the_rehearsal_steps_a_copy_of_the_state_machine_on_the_shadows_result(
    tmp_path, monkeypatch
):
    """The rest of the tick's code is rehearsed too: a copy of the state machine steps on what
    the shadow's tick gave, with the inputs the tick would build; the real one is untouched
    (here PX4 has left offboard: the copy starts its grace time, the real one does not)."""
    from onboard.runtime.state_machine import OffboardStateMachine, State

    rt = _runtime(tmp_path)
    try:
        rt.scheduler._next_s = time.perf_counter() + 10.0
        rt._refresh_shadow()
        f = rt.fcs
        f.heartbeat_rx_s = f.last_rx_s = rt.clock.now()
        f.armed, f.custom_mode = True, 4 << 16  # armed, PX4 in auto (not offboard)
        rt.sm.state = State.INTERCEPT
        rt.target_size_frac = 0.3
        before = dict(vars(rt.sm))
        stepped = []
        plain_step = OffboardStateMachine.step

        def step(self, inputs):
            stepped.append((self, inputs))
            return plain_step(self, inputs)

        monkeypatch.setattr(OffboardStateMachine, "step", step)
        assert rt._rehearse() is True
        assert len(stepped) == 1
        copy_, inputs = stepped[0]
        assert copy_ is not rt.sm and copy_._offboard_gone_s is not None  # the copy stepped
        assert vars(rt.sm) == before and rt.sm._offboard_gone_s is None  # the real one did not
        assert inputs.armed and not inputs.offboard and inputs.target_size_frac == 0.3
        assert inputs.speed_m_s == pytest.approx(float(np.linalg.norm(f.vel_enu_m_s)))
        assert inputs.tracking == (rt.rehearsal.shadow.mode is LoopMode.TRACKING)
        assert rt.rehearsal.errors == 0
        rt.tick()  # the tick builds the same inputs for the real one
        real, inputs = stepped[1]
        assert real is rt.sm and rt.sm._offboard_gone_s is not None
        assert inputs.armed and not inputs.offboard and inputs.target_size_frac == 0.3
    finally:
        rt.fc.close()


def test_without_rehearsal_the_scheduler_wakes_at_the_spin(tmp_path):
    rt = _runtime(tmp_path, rehearse=False)
    try:
        assert rt.rehearsal is None and rt.scheduler.rehearse is None
        assert rt.scheduler.rehearse_lead_s == 0.0
        rt.scheduler._next_s = 1e9
        rt._refresh_shadow()  # nothing to do
        assert rt.stats()["rehearse"] is False and rt.stats()["rehearsals"] is None
    finally:
        rt.fc.close()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="libc's sendto and recv")
def test_the_rehearsal_sends_its_frame_to_a_socket_of_its_own_never_to_px4(tmp_path):
    """The setpoint's send rehearsed (MavLink.rehearse_send): the rehearsal's frame goes from
    the link's socket to the runtime's own, read and dropped in the slack, and not once the
    deadline is near; PX4 gets only the real setpoints, numbered as without the rehearsals."""
    px4 = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    px4.bind(("127.0.0.1", 0))
    px4.settimeout(0.2)
    rt = _runtime(tmp_path, fc_port=px4.getsockname()[1])
    try:
        assert rt.fc.prepare_send_rehearsal() is None  # run() opens it before the loop
        rt.scheduler._next_s = time.perf_counter() + 1.0
        rt._refresh_shadow()
        assert rt._send_command(np.array([0.0, 0.0, 0.0]), 0.5, 1.0)  # the first setpoint
        assert rt._rehearse() and rt._rehearse()
        assert rt.rehearsal.sends == 2 and rt.stats()["rehearsed_sends"] == 2
        time.sleep(0.01)
        assert rt.fc.drain_rehearsals() == 2  # they went to the runtime's own socket
        rt.scheduler._next_s = time.perf_counter() + 0.25 * REHEARSED_SEND_MIN_LEAD_S
        assert rt._rehearse() and rt.rehearsal.sends == 2 and rt.rehearsal.runs == 3  # too near
        rt.scheduler._next_s = time.perf_counter() + 1.0
        rt.scheduler.input_begins()  # a fusion coming in: its early tick comes first
        assert rt._rehearse() and rt.rehearsal.sends == 2 and rt.rehearsal.runs == 4
        rt.scheduler.input_done()
        assert rt._send_command(np.array([0.1, -0.2, 0.3]), 0.55, 1.25)
        got = [mavlink.MAVLink(None).parse_char(px4.recvfrom(2048)[0]) for _ in range(2)]
        assert [m.get_type() for m in got] == ["SET_ATTITUDE_TARGET"] * 2
        assert [(m.time_boot_ms, m.get_seq()) for m in got] == [(1000, 0), (1250, 1)]
        # FLU -> FRD: the real command as it would have been without the rehearsals
        m = got[1]
        assert (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate) == pytest.approx(
            (0.1, 0.2, -0.3)
        )
        with pytest.raises(TimeoutError):
            px4.recvfrom(2048)  # and nothing else reached PX4
        assert rt.commands_sent == 2 and rt.rehearsal.errors == 0
    finally:
        rt.fc.close()
        px4.close()


def test_the_loop_is_built_in_the_slack_once_the_camera_gives_its_size(tmp_path):
    """The loop is built after a tick, in the slack, as soon as a frame gives the camera's
    size (README "Session 21": a tick that built the loop overran once); its shadow is taken
    in a later slack."""
    from onboard.runtime.camera import Frame

    cfg = RuntimeConfig(
        fc_url=f"udpout:127.0.0.1:{free_port()}",
        camera="sitl://127.0.0.1:9",  # never opened: run() is not called
        params_path=tmp_path / "params.toml",
    )
    rt = OnboardRuntime(cfg, log=lambda _s: None)
    try:
        sched = rt.scheduler
        sched._next_s = time.perf_counter() + 1.0
        assert rt._prepare_loop() is False and rt.loop is None  # no frame: no size yet
        now = rt.clock.now()
        rt.camera.last_frame = Frame(1, now, now, np.zeros((360, 480, 3), np.uint8))
        sched._next_s = time.perf_counter()  # the next wake-up is due: not now
        assert rt._prepare_loop() is False and rt.loop is None
        sched._next_s = time.perf_counter() + 1.0
        assert rt._prepare_loop() is True
        loop = rt.loop
        assert loop is not None and (loop.camera.width_px, loop.camera.height_px) == (480, 360)
        assert ("info", "camera 480x360, law png: loop ready") in list(rt._events)
        assert rt._prepare_loop() is False and rt.loop is loop  # built once
        rt._refresh_shadow()
        assert rt.rehearsal.shadow is not None
    finally:
        rt.fc.close()


def test_the_warm_up_flies_a_throwaway_loop_through_tracking_and_packs_its_setpoints():
    """warm_up (run(), before the loop runs) takes the code's first runs on a throwaway loop:
    it tracks (detections fused), every setpoint passes the output guard, and the runtime's
    own loop is not touched (it does not exist yet)."""
    from onboard.estimation.dkf import FusionResult
    from onboard.runtime.rehearsal import WARM_UP_TICKS, warm_up

    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, keep_records=False)
    loop = sim.loop
    assert warm_up(loop, 0.005) == WARM_UP_TICKS
    assert loop.acquired and loop.mode is LoopMode.TRACKING
    counts = loop.dkf.counts
    assert counts[FusionResult.INITIALISED] == 1 and counts[FusionResult.ACCEPTED] == 3


def test_a_failing_warm_up_is_a_warning_and_the_runtime_still_runs(tmp_path, monkeypatch):
    import onboard.runtime.runner as runner

    def broken(*_a, **_k):
        raise FloatingPointError("a bad throwaway loop")

    monkeypatch.setattr(runner, "warm_up", broken)
    rt = OnboardRuntime(
        RuntimeConfig(
            fc_url=f"udpout:127.0.0.1:{free_port()}",
            camera="sitl://127.0.0.1:9",  # nothing there: no frame, no loop
            params_path=tmp_path / "params.toml",
        ),
        log=lambda _s: None,
    )
    warnings = []
    real_event = rt._event
    monkeypatch.setattr(
        rt,
        "_event",
        lambda sev, text: (
            (warnings.append(text) if sev == "warning" else None) or real_event(sev, text)
        ),
    )
    assert rt.run(duration_s=0.2) == 0
    assert "warm-up failed (FloatingPointError: a bad throwaway loop)" in warnings
    assert rt.timing.tick_work_s  # it ticked
