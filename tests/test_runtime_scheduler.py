"""The onboard control thread's scheduler (onboard/runtime/scheduler.py): deadlines on a
fixed grid, re-anchoring after a stall, garbage collection held and handed back, other threads
held off while a tick runs."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
import threading
import time

import pytest

from onboard.runtime.scheduler import PeriodicScheduler, keep_off, split_cpus


def test_ticks_start_no_earlier_than_their_deadlines_on_a_fixed_grid():
    period = 0.002
    sched = PeriodicScheduler(period)
    sched.start()
    try:
        first = sched.wait()
        starts = [sched.wait() for _ in range(5)]
    finally:
        sched.stop()
    for k, s in enumerate(starts, start=1):
        assert s >= first + k * period - 1e-4  # never early (first is within the spin of 0)


def test_a_stall_re_anchors_instead_of_bursting():
    period = 0.002
    sched = PeriodicScheduler(period)
    sched.start()
    try:
        sched.wait()
        time.sleep(5 * period)  # a tick that took 2.5 periods too long
        after_stall = sched.wait()
        nxt = sched.wait()
    finally:
        sched.stop()
    assert sched.stalls >= 1
    assert nxt >= after_stall + period - 1e-4  # the next tick is a full period later


def test_other_threads_wait_for_the_tick_to_be_over():
    """A thread asking for slack while the control thread ticks goes on only after the tick
    (ordering, not timing: the tick records its end before after_tick lets the thread go)."""
    sched = PeriodicScheduler(0.05)
    log: list[str] = []
    asked = threading.Event()

    def helper() -> None:
        asked.set()
        sched.wait_for_slack()
        log.append("helper")

    sched.start()
    try:
        sched.wait()
        t = threading.Thread(target=helper)
        t.start()
        asked.wait(2.0)
        time.sleep(0.01)  # a long tick: the helper must still wait
        log.append("tick over")
        sched.after_tick()
        t.join(2.0)
        log.append("helper gone")
        slack = sched.wait_for_slack()  # the control thread asleep, ~40 ms off: at once
        log.append("slack")
    finally:
        sched.stop()
    assert log == ["tick over", "helper", "helper gone", "slack"]
    # how long the slack lasts: to the wake-up (spin before the deadline) less the lead
    assert 0.0 < slack < 0.05 - sched.spin_s
    assert sched.wait_for_slack() is None  # stopped: at once


def test_work_that_would_run_into_the_wake_up_waits_for_the_tick():
    """A piece of work of ``need_s`` goes at once only when it ends before the control thread
    wakes (less the lead); one that would run into the wake-up waits for the tick to be over
    (it would hold the GIL, or the loop's lock, as the thread wakes to rehearse and tick)."""
    from onboard.runtime.scheduler import SLACK_LEAD_S

    from .test_runtime_early_tick import FakeClock, P

    clock = FakeClock()
    lead = 0.0003
    sched = PeriodicScheduler(
        P, clock=clock.now, block=clock.block, rehearse=lambda: True, rehearse_lead_s=lead
    )
    sched.start()
    log: list[str] = []
    try:
        sched.wait()
        sched.after_tick()
        clock.t += 0.001  # 1 ms into the period
        wake_in = sched._next_s - sched.spin_s - lead - clock.t
        fits = wake_in - SLACK_LEAD_S - 0.0005  # 0.5 ms of work still ends before the lead
        assert sched.wait_for_slack(0.0005) == pytest.approx(fits, abs=1e-5)
        assert sched.wait_for_slack() == pytest.approx(fits + 0.0005, abs=1e-5)
        too_long = wake_in  # would end after the wake-up

        def helper() -> None:
            sched.wait_for_slack(too_long)
            log.append("helper")

        t = threading.Thread(target=helper)
        t.start()
        t.join(0.2)
        assert t.is_alive() and log == []  # held, not let into the wake-up
        sched.wait()
        log.append("tick")
        sched.after_tick()
        t.join(2.0)
    finally:
        sched.stop()
    assert log == ["tick", "helper"]


def test_collection_is_held_during_the_loop_and_handed_back():
    enabled = gc.isenabled()
    interval = sys.getswitchinterval()
    sched = PeriodicScheduler(0.005)
    assert sched.start() is None  # no real-time priority asked: nothing refused
    try:
        assert not gc.isenabled()
        assert gc.get_freeze_count() > 0
    finally:
        sched.stop()
    assert gc.isenabled() == enabled
    assert gc.get_freeze_count() == 0
    assert sys.getswitchinterval() == interval


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl's timer slack")
def test_the_control_threads_sleeps_end_when_asked_during_the_loop_only():
    from onboard.runtime.scheduler import set_timer_slack_ns

    before = set_timer_slack_ns(50_000)  # the kernel's default, whatever this thread had
    sched = PeriodicScheduler(0.005)
    try:
        sched.start()
        try:
            assert set_timer_slack_ns(1) == 1  # the loop set it: 1 ns
        finally:
            sched.stop()
        assert set_timer_slack_ns(50_000) == 50_000  # handed back
    finally:
        set_timer_slack_ns(before)


def test_bad_period_is_refused():
    with pytest.raises(ValueError):
        PeriodicScheduler(0.0)


def test_the_control_thread_gets_the_highest_cpu_and_the_others_the_rest():
    assert split_cpus({0, 1}) == ({1}, {0})
    assert split_cpus([3, 0, 2, 1]) == ({3}, {0, 1, 2})
    assert split_cpus({5, 9}) == ({9}, {5})
    assert split_cpus({4}) is None and split_cpus(()) is None  # nothing to split


needs_affinity = pytest.mark.skipif(
    not hasattr(os, "sched_getaffinity") or not os.path.isdir("/proc/self/task"),
    reason="no affinity API or no /proc",
)


@needs_affinity
def test_a_refused_placement_is_a_note_and_changes_nothing():
    before = os.sched_getaffinity(0)
    note = keep_off({10**6}, -1)  # no such CPU
    assert note is not None and "CPU placement refused" in note
    assert os.sched_getaffinity(0) == before


@needs_affinity
def test_every_other_thread_is_kept_off_and_put_back():
    cpus = os.sched_getaffinity(0)
    if len(cpus) < 2:
        pytest.skip("one CPU: nothing to keep off")
    _, others = split_cpus(cpus)
    go = threading.Event()
    helper = threading.Thread(target=go.wait, daemon=True)
    helper.start()
    try:
        assert keep_off(others, threading.get_native_id()) is None
        assert os.sched_getaffinity(helper.native_id) == others
        assert os.sched_getaffinity(0) == cpus  # the excepted thread is left as it was
    finally:
        keep_off(cpus, -1)
        go.set()
    assert os.sched_getaffinity(0) == cpus


def test_the_binding_is_let_go_while_the_control_thread_waits_for_its_cpu_and_taken_again():
    from onboard.runtime.scheduler import BindingWatch

    w = BindingWatch(check_every_s=0.5, max_wait_fraction=0.05, unbound_for_s=10.0,
                     unbound_max_s=40.0)  # fmt: skip
    assert w.due(0.0) and w.step(0.0, 3.0) is None  # the first look starts a window
    assert w.bound and not w.due(0.49) and w.step(0.49, 9.0) is None  # not yet
    assert w.step(0.5, 3.0 + 0.024) is None  # 4.8 % of the half second waiting: stays bound
    assert w.last_wait_fraction == pytest.approx(0.048)
    assert w.step(1.0, 3.024 + 0.026) is False  # 5.2 %: to be freed ...
    assert w.bound and w.escapes == 0  # ... once the runtime has done it
    w.applied(False, 1.0, 3.05)
    assert not w.bound and w.escapes == 1 and w.max_wait_fraction_seen == pytest.approx(0.052)
    assert not w.due(10.99) and w.step(10.99, 5.0) is None  # free for ten seconds
    assert w.step(11.0, 5.0) is True  # then to be bound again
    w.applied(True, 11.0, 5.0)  # looked at afresh from there: what it waited free not counted
    assert w.bound and w.step(11.5, 5.0 + 0.5) is False  # the program still there
    w.applied(False, 11.5, 5.5)
    assert w.unbound_for_s == 20.0 and w.escapes == 2  # free twice as long
    assert not w.due(31.49) and w.step(31.5, 6.0) is True
    w.applied(True, 31.5, 6.0)
    assert w.step(32.0, 6.5) is False
    w.applied(False, 32.0, 6.5)
    assert w.unbound_for_s == 40.0  # and again, up to the longest
    assert w.step(72.0, 7.0) is True
    w.applied(True, 72.0, 7.0)
    assert w.step(72.5, 7.5) is False
    w.applied(False, 72.5, 7.5)
    assert w.unbound_for_s == 40.0 and w.escapes == 4
    assert w.step(112.5, 7.5) is True
    w.applied(True, 112.5, 7.5)
    assert w.step(113.0, 7.5 + 0.001) is None  # gone: bound, and back to ten seconds
    assert w.unbound_for_s == 10.0 and w.bound


@pytest.mark.skipif(
    not os.path.exists("/proc/thread-self/schedstat")
    or not hasattr(os, "sched_setaffinity")
    or keep_off(os.sched_getaffinity(0), -1) is not None,  # placement allowed here
    reason="Linux's schedstat and CPU placement",
)
def test_the_run_delay_is_the_time_this_thread_waited_for_its_cpu():
    from onboard.runtime.scheduler import run_delay_s

    cpus = os.sched_getaffinity(0)
    cpu = min(cpus)
    spin = (
        f"import os, time\nos.sched_setaffinity(0, {{{cpu}}})\n"
        "end = time.time() + 0.6\nwhile time.time() < end: pass"
    )
    os.sched_setaffinity(0, {cpu})
    try:
        before = run_delay_s()
        hog = subprocess.Popen([sys.executable, "-c", spin])  # spins on this thread's CPU
        end = time.perf_counter() + 0.4
        while time.perf_counter() < end:
            sum(range(1000))
        after = run_delay_s()
        hog.wait()
    finally:
        os.sched_setaffinity(0, cpus)
    assert before is not None and after is not None
    assert after - before > 0.02  # 0.4 s sharing one CPU with a spinning process
