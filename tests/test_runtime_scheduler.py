"""The control thread's grid on a fake clock: absolute deadlines, late ticks counted and the
next deadline the next multiple (no catch-up burst), the hold until the next deadline, the
injected wake-up delays, and garbage collection held during the loop."""

import gc
import itertools

import pytest

from onboard.runtime.faults import WakeDelayConfig, WakeDelays
from onboard.runtime.scheduler import PeriodicScheduler

P = 0.005


class FakeClock:
    """Monotonic seconds; a sleep to a deadline ends there, plus the next queued lateness."""

    def __init__(self) -> None:
        self.t = 100.0
        self.late: list[float] = []
        self.slept_to: list[float] = []

    def now(self) -> float:
        return self.t

    def sleep_until(self, deadline_s: float) -> None:
        self.slept_to.append(deadline_s)
        self.t = max(self.t, deadline_s) + (self.late.pop(0) if self.late else 0.0)


def _sched(clock: FakeClock, **kw) -> PeriodicScheduler:
    s = PeriodicScheduler(P, clock=clock.now, sleep_until=clock.sleep_until, **kw)
    s.start()
    return s


def test_ticks_start_at_their_absolute_deadlines():
    clock = FakeClock()
    sched = _sched(clock)
    try:
        t0 = clock.t
        starts = []
        for _ in range(5):
            starts.append(sched.wait())
            assert sched.hold_s(starts[-1]) == pytest.approx(P, abs=1e-12)
            clock.t += 0.3 * P  # the tick's work does not push the grid
        assert starts == pytest.approx([t0 + k * P for k in range(5)], abs=1e-12)
        assert sched.late_ticks == 0 and sched.missed_deadlines == 0
    finally:
        sched.stop()


def test_a_late_tick_is_counted_and_the_next_deadline_is_the_next_multiple():
    clock = FakeClock()
    sched = _sched(clock)
    try:
        t0 = clock.t
        for _ in range(3):
            sched.wait()
        clock.late = [2.5 * P]  # the fourth wake-up (deadline 3 P) comes 2.5 periods late
        start = sched.wait()
        assert start == pytest.approx(t0 + 5.5 * P, abs=1e-12)
        assert sched.late_ticks == 1 and sched.missed_deadlines == 2
        # held until the next multiple (6 P) plus the mean recent lateness (0, 0, 0 and this
        # one's counted as a period: P / 4), not a whole period; then on the grid, no burst
        assert sched.hold_s(start) == pytest.approx(0.75 * P, abs=1e-12)
        assert sched.wait() == pytest.approx(t0 + 6 * P, abs=1e-12)
        assert sched.wait() == pytest.approx(t0 + 7 * P, abs=1e-12)
    finally:
        sched.stop()


def test_a_tick_that_overran_is_followed_at_once_then_on_the_grid():
    clock = FakeClock()
    sched = _sched(clock)
    try:
        t0 = clock.t
        sched.wait()
        clock.t += 1.3 * P  # the tick ran 1.3 periods: its successor's deadline has passed
        start = sched.wait()
        assert start == pytest.approx(t0 + 1.3 * P, abs=1e-12)  # at once, less than P late
        assert sched.late_ticks == 0
        assert sched.hold_s(start) == pytest.approx(0.7 * P + 0.15 * P, abs=1e-12)
        assert sched.wait() == pytest.approx(t0 + 2 * P, abs=1e-12)
    finally:
        sched.stop()


def test_injected_delays_postpone_the_wake_ups_and_are_summed():
    clock = FakeClock()
    cfg = WakeDelayConfig(p99_s=0.0, stall_s=0.0301, stall_every_s=1.0, freeze_s=0.1512,
                          freeze_at_s=0.5)  # fmt: skip
    sched = _sched(clock, delays=WakeDelays(1, cfg))
    try:
        t0 = clock.t
        starts = [sched.wait() for _ in range(400)]
        late = [s - t0 for s in starts]
        assert sched.delays.freezes == 1 and sched.delays.stalls >= 1
        assert sched.injected_s == pytest.approx(0.1512 + 0.0301 * sched.delays.stalls, abs=1e-9)
        gaps = [b - a for a, b in itertools.pairwise(late)]
        assert max(gaps) == pytest.approx(P + 0.1512, abs=1e-9)  # the freeze, then no burst:
        assert min(gaps) > 0.5 * P  # the tick after each delay waits for the next multiple
        short = [g for g in gaps if g < P - 1e-9]
        assert len(short) == sched.delays.stalls + sched.delays.freezes
    finally:
        sched.stop()


def test_the_delays_are_seeded_with_the_stated_p99_stalls_and_one_freeze():
    a = WakeDelays(7)
    b = WakeDelays(7)
    ts = [k * P for k in range(2000)]  # 10 s at 200 Hz
    da = [a.next_s(t) for t in ts]
    assert da == [b.next_s(t) for t in ts]  # the same seed, the same delays
    assert da != [WakeDelays(8).next_s(t) for t in ts]
    assert a.stalls == 9 and a.freezes == 1  # at 1, 2, ..., 9 s; the freeze at 4 s
    base = sorted(d for d in da if d < 0.02)
    p99 = base[int(0.99 * len(base))]
    assert 0.0035 <= p99 <= 0.0065  # 5 ms, within the sampling spread of 2000 draws
    assert max(da) >= 0.15


def test_collection_is_held_during_the_loop_and_handed_back():
    was = gc.isenabled()
    clock = FakeClock()
    sched = _sched(clock)
    try:
        assert not gc.isenabled()
        sched.wait()
        clock.t += 0.6  # due, with the period's slack left: collected after the tick
        sched._next_s = clock.t + P
        sched.after_tick()
        assert sched.gc_runs == 1
    finally:
        sched.stop()
    assert gc.isenabled() == was


def test_bad_period_is_refused():
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError):
            PeriodicScheduler(bad)


def test_the_real_clock_sleeps_to_absolute_deadlines():
    """On this machine's monotonic clock: no tick starts before its deadline (how late is a
    figure for ``onboard check-rt``, not asserted)."""
    sched = PeriodicScheduler(0.002)
    sched.start()
    try:
        for _ in range(20):
            deadline = sched.next_deadline_s
            assert sched.wait() >= deadline
    finally:
        sched.stop()
