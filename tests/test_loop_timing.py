"""LoopTiming's share of the setpoint's send in the tick's work (``groundstation bench --sitl``
prints it: how much of the slowest ticks is the send)."""

from __future__ import annotations

import pytest

from onboard.runtime.timing import LoopTiming


def _tick(timing: LoopTiming, start_s: float, work_ms: float, send_ms: float | None) -> None:
    timing.tick_started(start_s)
    if send_ms is not None:
        timing.setpoint_sent(send_ms / 1000.0)
    timing.tick_done(work_ms / 1000.0)


def test_the_send_is_timed_per_tick_and_its_share_of_the_slowest_ticks_reported():
    timing = LoopTiming(0.005, keep=1000)
    t = 0.0
    for i in range(100):  # 0.100 .. 0.199 ms of work, 0.05 ms of it the send
        _tick(timing, t, 0.1 + i * 0.001, 0.05)
        t += 0.005
    _tick(timing, t, 0.6, 0.4)
    _tick(timing, t + 0.005, 0.7, 0.5)  # the slowest 1 % of 103 ticks: this one and the next
    _tick(timing, t + 0.010, 0.8, None)  # no setpoint sent (the state machine sent none)
    fig = timing.figures()
    assert fig["setpoint_send_median_ms"] == pytest.approx(0.05)
    assert fig["setpoint_send_p99_ms"] == pytest.approx(0.4)  # element 100 of the 102 sends
    assert fig["tick_work_max_ms"] == pytest.approx(0.8)
    assert fig["slowest_1pc_work_mean_ms"] == pytest.approx(0.75)
    assert fig["slowest_1pc_send_mean_ms"] == pytest.approx(0.25)  # 0.5 and none


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
    assert fig["tick_work_max_ms"] is None
