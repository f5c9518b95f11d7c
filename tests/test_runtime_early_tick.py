"""The early tick (#16 item 5): a fused detection brings the control tick forward and the grid
re-anchors one period after it (onboard/runtime/scheduler.py), the loop flies that command for
its hold, not the time since the last tick (onboard/loop.py), and the runtime's accounting
keeps early ticks apart (onboard/runtime/timing.py). Driven by a fake clock: no timing is
asserted, only the order and the instants the scheduler chose on that clock."""

from __future__ import annotations

import itertools
import math
import threading

import numpy as np
import pytest

from onboard.camera_model import CameraModel
from onboard.datatypes import Detection, VehicleParams, VehicleState
from onboard.gains import Gains
from onboard.geometry import attitude_from_yaw_pitch_roll, rotmat_to_quat
from onboard.loop import InterceptionLoop
from onboard.runtime.scheduler import PeriodicScheduler
from onboard.runtime.timing import LoopTiming

P = 0.005  # 200 Hz
STEP = 1e-6  # the fake clock moves this much per reading (a spin ends)


class FakeClock:
    """Time that moves only when read (a microsecond), slept or worked; requests scheduled
    with :meth:`at` fire when the time passes them, waking a blocked sleep as a notify would."""

    def __init__(self) -> None:
        self.t = 100.0
        self._events: list[tuple[float, object]] = []

    def at(self, t: float, fn) -> None:
        self._events.append((t, fn))
        self._events.sort(key=lambda e: e[0])

    def _fire(self) -> bool:
        fired = False
        while self._events and self._events[0][0] <= self.t:
            self._events.pop(0)[1]()
            fired = True
        return fired

    def now(self) -> float:
        self.t += STEP
        self._fire()
        return self.t

    def block(self, timeout_s: float) -> None:
        end = self.t + timeout_s
        if self._events and self._events[0][0] < end:
            self.t = max(self.t, self._events[0][0])  # woken by the request
        else:
            self.t = end
        self._fire()

    def work(self, s: float) -> None:
        self.t += s
        self._fire()


def _scheduler(clock: FakeClock, **kw) -> PeriodicScheduler:
    return PeriodicScheduler(P, clock=clock.now, block=clock.block, **kw)


def _run(clock: FakeClock, sched: PeriodicScheduler, n: int, work_s: float = 0.0003):
    """n ticks; each takes its requests in at its start (served), then works."""
    starts = []
    sched.start()
    try:
        for _ in range(n):
            start = sched.wait()
            sched.served()
            starts.append((round(start - 100.0, 6), sched.early))
            clock.work(work_s)
            sched.after_tick()
    finally:
        sched.stop()
    return starts


def _tick(sched, clock, work_s: float = 0.0) -> None:
    """One tick on the control thread: woken, served, ``work_s`` of work, its slack begun."""
    sched.wait()
    sched.served()
    if work_s:
        clock.work(work_s)
    sched.after_tick()


def test_a_request_ticks_at_once_and_re_anchors_the_grid():
    clock = FakeClock()
    sched = _scheduler(clock)
    clock.at(100.0122, sched.request_tick)  # between the grid's 10 and 15 ms
    starts = _run(clock, sched, 6)
    t = [s for s, _ in starts]
    assert [e for _, e in starts] == [False, False, False, True, False, False]
    assert t[:3] == pytest.approx([0.0, 0.005, 0.010], abs=1e-5)
    assert t[3] == pytest.approx(0.0122, abs=1e-5)  # at once, not at 15 ms
    assert t[4] - t[3] == pytest.approx(P, abs=1e-5)  # one period after the early tick
    assert t[5] - t[4] == pytest.approx(P, abs=1e-5)
    assert sched.early_ticks == 1 and sched.stalls == 0


def test_a_request_just_before_a_deadline_replaces_that_tick_no_double_tick():
    clock = FakeClock()
    sched = _scheduler(clock)
    clock.at(100.0099, sched.request_tick)  # 0.1 ms before the 10 ms deadline (in the spin)
    t = [s for s, _ in _run(clock, sched, 5)]
    assert t[2] == pytest.approx(0.0099, abs=1e-5)
    assert t[3] == pytest.approx(0.0149, abs=1e-5)  # no tick at 10 ms nor at 15 ms
    assert all(b - a > 0.8 * P for a, b in itertools.pairwise(t[2:]))


def test_a_request_the_tick_already_took_in_is_not_served_twice():
    """The camera thread fuses and requests under the loop's lock; a tick that takes the lock
    afterwards has the fusion in it (served): no early tick follows it."""
    clock = FakeClock()
    sched = _scheduler(clock)
    starts = []
    sched.start()
    try:
        for k in range(4):
            start = sched.wait()
            if k == 1:
                sched.request_tick()  # fused while the tick waited for the lock
            sched.served()
            starts.append(round(start - 100.0, 6))
            clock.work(0.0003)
            sched.after_tick()
    finally:
        sched.stop()
    assert starts == pytest.approx([0.0, 0.005, 0.010, 0.015], abs=1e-5)
    assert sched.early_ticks == 0


def test_a_request_during_a_tick_gets_one_early_tick_after_the_minimum_gap():
    clock = FakeClock()
    sched = _scheduler(clock)  # minimum gap: a fifth of the period, 1 ms
    clock.at(100.0051, sched.request_tick)  # 0.1 ms into the 5 ms tick (after its served())
    clock.at(100.00511, sched.request_tick)  # a second detection before the early tick
    starts = _run(clock, sched, 4)
    t = [s for s, _ in starts]
    assert [e for _, e in starts] == [False, False, True, False]
    assert t[2] == pytest.approx(0.005 + sched.min_gap_s, abs=1e-5)
    assert t[3] == pytest.approx(t[2] + P, abs=1e-5)
    assert sched.early_ticks == 1


def test_a_stream_of_requests_never_ticks_faster_than_the_gap_nor_slower_than_the_grid():
    clock = FakeClock()
    sched = _scheduler(clock)
    for k in range(200):  # a request every 0.3 ms for 60 ms
        clock.at(100.0 + 0.0003 * k, sched.request_tick)
    starts = _run(clock, sched, 80)
    t = [s for s, _ in starts]
    gaps = np.diff(t)
    assert gaps.min() >= sched.min_gap_s - 1e-5  # the control thread is never flooded
    assert gaps.max() <= P + 1e-5  # nor ever held past its deadline
    after = [s for s, _ in starts if s > 0.061]
    assert not any(e for s, e in starts if s > 0.061)  # back on a grid once they stop
    assert np.diff(after) == pytest.approx(P, abs=1e-5)


def test_a_stall_is_still_a_stall_and_re_anchors():
    clock = FakeClock()
    sched = _scheduler(clock)
    sched.start()
    try:
        sched.wait()
        sched.served()
        clock.work(0.012)  # a tick that ran 2.4 periods
        sched.request_tick()  # and a detection meanwhile
        after_stall = sched.wait()
        early_flag = sched.early
        sched.served()
        clock.work(0.0003)
        nxt = sched.wait()
    finally:
        sched.stop()
    assert sched.stalls == 1 and not early_flag
    assert nxt - after_stall == pytest.approx(P, abs=1e-5)


def _waiting_for_slack(sched: PeriodicScheduler, log: list[str]) -> threading.Thread:
    """Another thread that waits for slack, then logs "helper"; returned once it has had
    50 ms to get past the wait."""
    asked = threading.Event()

    def helper() -> None:
        asked.set()
        sched.wait_for_slack()
        log.append("helper")

    th = threading.Thread(target=helper)
    th.start()
    asked.wait(2.0)
    th.join(0.05)
    return th


def test_other_threads_wait_while_an_early_tick_is_pending():
    """wait_for_slack holds another thread off while a request is pending (the control thread
    is about to wake), and lets it go when that tick is over."""
    clock = FakeClock()
    sched = _scheduler(clock)
    log: list[str] = []
    sched.start()
    try:
        _tick(sched, clock, 0.0003)
        sched.wait_for_slack()  # asleep with 4.7 ms to go: at once
        log.append("slack")
        sched.request_tick()
        th = _waiting_for_slack(sched, log)  # still held: the early tick has not run
        log.append("early tick")
        _tick(sched, clock)
        th.join(2.0)
    finally:
        sched.stop()
    assert log == ["slack", "early tick", "helper"]


# ---------------------------------------------------------------------- ticked where fused
def test_the_fusing_thread_ticks_itself_while_the_control_thread_sleeps():
    """tick_here: the early tick starts at once on the thread that fused, the grid re-anchors
    one period after it, and the control thread, woken for the old deadline, sleeps on."""
    clock = FakeClock()
    sched = _scheduler(clock)
    here = []

    def fused() -> None:  # the camera thread, as run() has it
        start = sched.tick_here()
        here.append(None if start is None else round(start - 100.0, 6))
        clock.work(0.0003)
        sched.tick_here_done()

    clock.at(100.0072, fused)  # between the grid's 5 and 10 ms, the control thread asleep
    starts = _run(clock, sched, 4)
    assert here == pytest.approx([0.0072], abs=1e-5)
    t = [s for s, _ in starts]
    assert t == pytest.approx([0.0, 0.005, 0.0122, 0.0172], abs=1e-5)  # not 10 ms
    assert not any(e for _, e in starts)  # the control thread's ticks are on the grid
    assert sched.early_ticks == sched.ticks_here == 1 and sched.stalls == 0


@pytest.mark.parametrize(
    ("when", "why"),
    [
        (100.00505, "the control thread is ticking"),
        (100.0098, "the control thread is awake for its deadline (within the spin)"),
        (100.0052, "within the minimum gap after the last tick"),
    ],
)
def test_the_fusing_thread_leaves_the_tick_to_the_control_thread(when, why):
    clock = FakeClock()
    sched = _scheduler(clock)
    here = []
    clock.at(when, lambda: here.append(sched.tick_here()))
    starts = _run(clock, sched, 4, work_s=0.0003)
    assert here == [None], why
    assert [s for s, _ in starts] == pytest.approx([0.0, 0.005, 0.010, 0.015], abs=1e-5)
    assert sched.ticks_here == 0


def test_a_pending_request_is_left_to_the_control_thread():
    clock = FakeClock()
    sched = _scheduler(clock)
    sched.start()
    try:
        _tick(sched, clock)
        sched.request_tick()
        assert sched.tick_here() is None  # the control thread is waking for it
    finally:
        sched.stop()


def test_other_threads_wait_while_the_fusing_thread_ticks():
    clock = FakeClock()
    sched = _scheduler(clock)
    log: list[str] = []
    sched.start()
    try:
        _tick(sched, clock, 0.0003)
        clock.work(0.002)  # asleep, 2.7 ms to go
        assert sched.tick_here() is not None
        th = _waiting_for_slack(sched, log)  # held while the tick runs
        log.append("tick here over")
        sched.tick_here_done()
        th.join(2.0)
    finally:
        sched.stop()
    assert log == ["tick here over", "helper"]


def test_a_tick_on_the_fusing_thread_that_overran_is_a_stall_not_a_burst():
    clock = FakeClock()
    sched = _scheduler(clock)

    def fused() -> None:
        sched.tick_here()
        clock.work(0.012)  # 2.4 periods
        sched.tick_here_done()

    clock.at(100.0072, fused)
    t = [s for s, _ in _run(clock, sched, 4)]
    assert t[:2] == pytest.approx([0.0, 0.005], abs=1e-5)
    assert t[2] == pytest.approx(0.0192, abs=1e-5)  # afresh from its end: no tick at 12.2 ms
    assert t[3] - t[2] == pytest.approx(P, abs=1e-5)
    assert sched.stalls == 1 and sched.ticks_here == 1


def test_the_control_thread_waits_out_a_tick_on_another_thread_asleep():
    """Its deadline coming while another thread's tick runs, the control thread sleeps until
    that tick is over (a handful of clock readings), then ticks: never spins against it."""
    import time

    reads = [0]

    def clock() -> float:
        reads[0] += 1
        return time.perf_counter()

    sched = PeriodicScheduler(P, clock=clock)
    starts: list[float] = []
    sched.start()
    try:
        _tick(sched, clock)
        time.sleep(0.0015)  # past the minimum gap
        t0 = sched.tick_here()
        assert t0 is not None
        th = threading.Thread(target=lambda: starts.append(sched.wait()))
        th.start()
        time.sleep(0.008)  # a tick of 8 ms on this thread: past the new deadline
        n = reads[0]
        sched.tick_here_done()
        th.join(2.0)
    finally:
        sched.stop()
    assert n < 100, n  # asleep (spinning read the clock thousands of times)
    assert len(starts) == 1 and starts[0] >= t0 + 0.008


def test_no_tick_starts_on_another_thread_while_the_slack_collects_garbage():
    import gc

    clock = FakeClock()
    sched = _scheduler(clock)
    offered = []

    def during_collection(phase, _info) -> None:
        if phase == "start":
            offered.append(sched.tick_here())
            if offered[-1] is not None:  # (it should not have started: end it at once)
                sched.tick_here_done()

    gc.callbacks.append(during_collection)
    try:
        _run(clock, sched, 120, work_s=0.0012)  # a young collection in the slack after 0.5 s
    finally:
        gc.callbacks.remove(during_collection)
    assert sched.gc_runs >= 1 and offered and all(o is None for o in offered)
    assert sched.ticks_here == 0


def test_timing_keeps_early_ticks_out_of_the_jitter_and_counts_overruns():
    timing = LoopTiming(P, keep=100)
    for start, early, work in [
        (0.0, False, 0.0003),
        (0.005, False, 0.0003),
        (0.0072, True, 0.0061),  # an early tick that overran
        (0.0122, False, 0.0003),
        (0.0172, False, 0.0003),
    ]:
        timing.tick_started(start, early)
        timing.tick_done(work, 0.0002 if early else None)
    fig = timing.figures()
    assert fig["early_ticks"] == 1 and fig["overruns"] == 1
    # which tick overran, and how little of it was its own CPU (the rest a wait)
    assert fig["overran_ticks"] == [
        {
            "woken_as": "early tick",
            "at_s": pytest.approx(0.0072),
            "work_ms": pytest.approx(6.1),
            "cpu_ms": pytest.approx(0.2),
        }
    ]
    assert fig["early_gap_median_ms"] == pytest.approx(2.2)
    assert fig["rate_hz"] == pytest.approx(200.0)
    assert fig["jitter_max_ms"] == pytest.approx(0.0, abs=1e-9)
    assert timing.loop_rate_hz() == pytest.approx(200.0)
    # the early tick's work is in the tick work and also reported apart
    assert fig["tick_work_p99_ms"] == pytest.approx(6.1)
    assert fig["early_tick_work_median_ms"] == pytest.approx(6.1)
    assert fig["early_tick_work_p99_ms"] == pytest.approx(6.1)
    assert fig["tick_work_median_ms"] == pytest.approx(0.3)


# ---------------------------------------------------------------------- the loop's hold
Q_NORTH = rotmat_to_quat(attitude_from_yaw_pitch_roll(math.pi / 2))
Q_NORTH_OFF = rotmat_to_quat(attitude_from_yaw_pitch_roll(math.pi / 2 + math.radians(0.05)))


def _tracking_loop() -> InterceptionLoop:
    # no velocity-latency prediction: v is the state's, whatever was commanded before
    loop = InterceptionLoop(CameraModel(), VehicleParams(), Gains(t_vel_lag=0.0), law="png")
    loop.tick(_state(0.0))
    loop.on_detection(Detection(0.0, (420.0, 300.0), (410, 290, 20, 20), 314.0))
    return loop


def _state(t: float, q=Q_NORTH) -> VehicleState:
    return VehicleState(t, np.array([0.0, 0.0, 10.0]), np.array([0.5, 3.0, 0.2]), q, np.zeros(3))


def _flown(ticks: list[tuple[float, float | None]], end_s: float, from_s: float, q_at=None):
    """Velocity change (m/s, ENU) the commands of ``ticks`` (time, hold) ask for between
    ``from_s`` and ``end_s``, each held until the next tick: sum of a_d x time held."""
    loop = _tracking_loop()
    dv = np.zeros(3)
    a_d = {}
    for t, hold in ticks:
        q = Q_NORTH_OFF if q_at is not None and abs(t - q_at) < 1e-9 else Q_NORTH
        a_d[t] = loop.tick(_state(t, q), hold_s=hold).accel_desired_enu_m_s2
    times = [t for t, _ in ticks] + [end_s]
    for (t, _), t_next in zip(ticks, times[1:], strict=False):
        if t >= from_s:
            dv += a_d[t] * (t_next - t)
    return dv, a_d


def test_an_early_tick_flies_the_grid_s_turn():
    """Commands on the grid (5 ms, the simulator's way) and with an early tick at 6 ms (the
    grid re-anchored to 11 ms, each command for a period) ask for the same velocity change
    over the same time: the early tick's LOS change carries what the cut-short 5 ms command
    did not fly."""
    grid = [(0.005 * k, None) for k in range(1, 5)]  # 5, 10, 15, 20 ms
    early = [(0.005, P), (0.006, P), (0.011, P), (0.016, P)]
    dv_grid, _ = _flown(grid, 0.021, 0.005)
    dv_early, _ = _flown(early, 0.021, 0.005)
    assert np.linalg.norm(dv_grid) > 0.01
    assert dv_early == pytest.approx(dv_grid, rel=0.03, abs=2e-4)


def test_an_early_tick_is_no_more_sensitive_to_one_sample_than_a_grid_tick():
    """An attitude sample off by 0.05 deg moves an early tick's command (held a period) as much
    as a grid tick's, not period / elapsed times as much, which is what dividing eq. 17 by the
    time since the last tick did (the withdrawn first version: a target lost one run in
    three)."""
    grid = [(0.005, None), (0.010, None)]
    _, a_clean = _flown(grid, 0.015, 0.0)
    _, a_off = _flown(grid, 0.015, 0.0, q_at=0.010)
    d_grid = np.linalg.norm(a_off[0.010] - a_clean[0.010])
    early = [(0.005, P), (0.006, P)]
    _, e_clean = _flown(early, 0.011, 0.0)
    _, e_off = _flown(early, 0.011, 0.0, q_at=0.006)
    d_early = np.linalg.norm(e_off[0.006] - e_clean[0.006])
    elapsed = [(0.005, None), (0.006, None)]  # eq. 17 over the 1 ms since the last tick
    _, x_clean = _flown(elapsed, 0.011, 0.0)
    _, x_off = _flown(elapsed, 0.011, 0.0, q_at=0.006)
    d_elapsed = np.linalg.norm(x_off[0.006] - x_clean[0.006])
    assert d_grid > 0.05  # the perturbation matters
    assert d_early == pytest.approx(d_grid, rel=0.25)
    assert d_elapsed > 3.0 * d_grid


@pytest.mark.parametrize("fused", [True, False])
def test_a_tick_falling_due_during_a_fusion_waits_for_it_asleep(fused):
    """A fusion running at the deadline: the tick starts when it is in (re-anchored there,
    counted as a grid tick, its lateness in the jitter), not on the lock as tick work."""
    clock = FakeClock()
    sched = _scheduler(clock)
    blocks: list[float] = []
    fake_block = clock.block

    def block(timeout_s: float) -> None:
        blocks.append(clock.t - 100.0)
        fake_block(timeout_s)

    sched._block = block
    clock.at(100.0098, sched.input_begins)  # in the spin before the 10 ms deadline
    if fused:
        clock.at(100.0104, lambda: (sched.request_tick(), sched.input_done()))
    else:
        clock.at(100.0104, lambda: sched.input_done())  # screened out: nothing fused
    starts = _run(clock, sched, 4)
    t = [s for s, _ in starts]
    assert [e for _, e in starts] == [False, False, False, False]
    assert t[2] == pytest.approx(0.0104, abs=1e-5)
    assert t[3] == pytest.approx(0.0154, abs=1e-5)
    assert sched.input_waits == 1 and sched.input_wait_max_s == pytest.approx(0.0004, abs=1e-5)
    assert sched.early_ticks == 0


def test_a_request_arriving_as_the_control_thread_goes_to_sleep_is_not_slept_through(
    monkeypatch,
):
    """wait() reads the request flag, then blocks: a request_tick() landing in between must
    wake it (return at once so wait() chooses again), not turn into a plain sleep for the
    whole timeout the caller chose for its deadline."""
    import onboard.runtime.scheduler as scheduler_mod

    slept: list[float] = []
    monkeypatch.setattr(scheduler_mod.time, "sleep", slept.append)
    sched = PeriodicScheduler(0.005)
    sched._block_saw_request = False  # the caller's timeout counted no request...
    sched.request_tick()  # ...and one came before the block took the lock
    sched._block_until_request(10.0)
    assert slept == []
    # a request the caller did count (waiting for the minimum gap) is a plain sleep
    sched._block_saw_request = True
    sched._block_until_request(0.001)
    assert slept == [0.001]


def _carried(ticks: list[tuple[float, float]]):
    """Tick a tracking loop at ``ticks`` (time, hold); per command the LOS change it asked the
    law for (d_los_elev, d_los_azim, rad), its hold, and the LOS angles of each tick."""
    loop = _tracking_loop()
    asked: list[tuple[float, float, float]] = []
    law = loop._law

    def recording_law(inp, gains):
        asked.append((inp.d_los_elev_rad, inp.d_los_azim_rad, inp.dt_s))
        return law(inp, gains)

    loop._law = recording_law
    q = []
    for t, hold in ticks:
        tel = loop.tick(_state(t), hold_s=hold)
        q.append((tel.los_elev_rad, tel.los_azim_rad))
    return asked, q


@pytest.mark.parametrize(
    "times",
    [
        [0.005, 0.0115, 0.0165, 0.0235, 0.0285, 0.0335],  # late by 1.5 ms, then 2 ms
        [0.005, 0.006, 0.011, 0.0175, 0.0185, 0.0235, 0.0295],  # early and late mixed
        [0.005, 0.010, 0.015, 0.020],  # on time: nothing carried
    ],
)
def test_the_turn_summed_over_commands_is_k_times_the_los_change_early_and_late(times):
    """Each command turns the velocity by K x its LOS change per hold for as long as it is
    held (until the next tick); with the carry, the LOS changes flown (each command's for the
    time it was held, the last one for its whole hold) add up to the LOS change between the
    first and the last tick, whether the ticks came early (cut short) or late (held longer)."""
    asked, q = _carried([(t, P) for t in times])
    assert len(asked) == len(times)
    assert all(hold == P for _, _, hold in asked)  # eq. 17's dt: the hold, early or late
    held = [*np.diff(times).tolist(), P]
    flown_y = sum(dy * h / hold for (dy, _, hold), h in zip(asked, held, strict=True))
    flown_z = sum(dz * h / hold for (_, dz, hold), h in zip(asked, held, strict=True))
    # the first command carries nothing: its LOS change is since the tick before the list's
    los_y = asked[0][0] + q[-1][0] - q[0][0]
    los_z = asked[0][1] + q[-1][1] - q[0][1]
    assert abs(los_y) + abs(los_z) > 1e-4  # the LOS does move
    assert flown_y == pytest.approx(los_y, rel=1e-9, abs=1e-15)
    assert flown_z == pytest.approx(los_z, rel=1e-9, abs=1e-15)
    if times == [0.005, 0.010, 0.015, 0.020]:  # on the grid: each command its own LOS change
        assert [a[0] for a in asked[1:]] == pytest.approx(np.diff([p[0] for p in q]).tolist())


def test_a_stall_takes_back_at_most_one_command_s_turn():
    """A tick four holds late (a stall): the excess would be three whole commands; at most one
    (MAX_LATE_CARRY) is taken off the next command, which is not flung the other way."""
    from onboard.loop import MAX_LATE_CARRY

    asked, q = _carried([(0.005, P), (0.010, P), (0.030, P)])
    (_, _, _), (dy0, dz0, _), (dy1, dz1, _) = asked
    raw_y, raw_z = q[2][0] - q[1][0], q[2][1] - q[1][1]
    assert MAX_LATE_CARRY == 1.0
    assert dy1 == pytest.approx(raw_y - dy0, rel=1e-9, abs=1e-15)
    assert dz1 == pytest.approx(raw_z - dz0, rel=1e-9, abs=1e-15)


def configs_of_onboard_run(monkeypatch, extra_argv: list[str]) -> list:
    """The RuntimeConfig ``onboard run --camera 0 --gcs '' <extra_argv>`` builds (the runtime
    replaced by one that only records its config)."""
    import signal

    import onboard.runtime.runner as runner_mod
    from onboard.cli import main

    seen = []

    class Captured:
        def __init__(self, config, log=None) -> None:
            seen.append(config)

        def stop(self) -> None:
            pass

        def run(self, duration_s=None) -> int:
            return 0

    monkeypatch.setattr(runner_mod, "OnboardRuntime", Captured)
    monkeypatch.setattr(signal, "signal", lambda *a: None)
    assert main(["run", "--camera", "0", "--gcs", "", *extra_argv]) == 0
    return seen


@pytest.mark.parametrize(("flag", "expected"), [(None, None), ("on", True), ("off", False)])
def test_onboard_run_early_tick_flag_reaches_the_runtime(monkeypatch, flag, expected):
    """``onboard run --early-tick on|off`` (default: RuntimeConfig's) sets the config."""
    from onboard.runtime.runner import RuntimeConfig

    seen = configs_of_onboard_run(monkeypatch, [] if flag is None else ["--early-tick", flag])
    default = RuntimeConfig.early_tick
    assert [c.early_tick for c in seen] == [default if expected is None else expected]


def test_onboard_run_refuses_a_bad_early_tick_value(capsys):
    from onboard.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["run", "--camera", "0", "--early-tick", "yes"])
    assert exc.value.code == 2
    assert "--early-tick" in capsys.readouterr().err
