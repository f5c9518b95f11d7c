"""LoopTiming's figures of the ticks that flew the vehicle (sent a setpoint) and the send's
share of their work (``groundstation bench --sitl`` judges the tick-work target on them)."""

from __future__ import annotations

import pytest

from onboard.runtime.timing import LoopTiming


def _tick(timing: LoopTiming, start_s: float, work_ms: float, send_ms: float | None) -> None:
    timing.tick_started(start_s)
    if send_ms is not None:
        timing.setpoint_sent(send_ms / 1000.0)
    timing.tick_done(work_ms / 1000.0)


def test_the_flying_ticks_and_the_sends_share_of_their_slowest_are_reported_apart():
    timing = LoopTiming(0.005, keep=1000)
    t = 0.0
    for i in range(100):  # 0.100 .. 0.199 ms of work, 0.05 ms of it the send
        _tick(timing, t, 0.1 + i * 0.001, 0.05)
        t += 0.005
    _tick(timing, t, 0.6, 0.4)  # the slowest 1 % of the 102 flying ticks: this one and the next
    _tick(timing, t + 0.005, 0.7, 0.5)
    _tick(timing, t + 0.010, 0.8, None)  # no setpoint sent (before the start, after the end)
    fig = timing.figures()
    assert fig["setpoint_send_median_ms"] == pytest.approx(0.05)
    assert fig["setpoint_send_p99_ms"] == pytest.approx(0.4)  # element 100 of the 102 sends
    assert fig["flying_ticks"] == 102
    assert fig["flying_tick_work_median_ms"] == pytest.approx(0.151)
    assert fig["flying_tick_work_p99_ms"] == pytest.approx(0.6)
    assert fig["flying_tick_work_max_ms"] == pytest.approx(0.7)  # the 0.8 flew nothing
    assert fig["tick_work_max_ms"] == pytest.approx(0.8)  # all ticks
    assert fig["tick_work_p99_ms"] == pytest.approx(0.7)
    assert fig["slowest_1pc_work_mean_ms"] == pytest.approx(0.65)
    assert fig["slowest_1pc_send_mean_ms"] == pytest.approx(0.45)


def test_a_send_is_counted_in_its_own_tick_only():
    """A send timed in one tick is not carried into the next, which sent nothing; nor is one
    timed outside a tick (a direct call) counted in the next tick."""
    timing = LoopTiming(0.005, keep=10)
    _tick(timing, 0.0, 0.2, 0.1)
    _tick(timing, 0.005, 0.3, None)
    timing.setpoint_sent(0.004)  # not within a started tick
    _tick(timing, 0.010, 0.25, None)
    sends = list(timing.send_s)
    assert sends[0] == pytest.approx(0.0001)
    assert all(s != s for s in sends[1:])  # NaN: no send in that tick
    assert timing.figures()["setpoint_send_p99_ms"] == pytest.approx(0.1)


def test_no_ticks_no_send_figures():
    fig = LoopTiming(0.005, keep=10).figures()
    assert fig["setpoint_send_median_ms"] is None and fig["setpoint_send_p99_ms"] is None
    assert fig["slowest_1pc_work_mean_ms"] is None and fig["slowest_1pc_send_mean_ms"] is None
    assert fig["tick_work_max_ms"] is None and fig["flying_tick_work_p99_ms"] is None
    assert fig["flying_ticks"] == 0
