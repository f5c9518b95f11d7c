"""The simulator session's telemetry publisher: paced sorties publish on a grid of simulated
time (one snapshot per publish period times the speed), each carrying a new state."""

from __future__ import annotations

import itertools
import math
import threading
import time

import pytest

from groundstation.app import session as session_mod
from groundstation.app.session import SimSession, SortieConfig
from groundstation.scenario import load_scenario


def _fly(
    monkeypatch, speed: str, sim_s: float, slow_every: int = 0
) -> tuple[list[float], SimSession]:
    # never starved: every crossing of the grid publishes, however loaded the machine
    monkeypatch.setattr(session_mod, "BEHIND_TOLERANCE_S", math.inf)
    if slow_every:  # every n-th control period takes 60 ms of wall (a core taken by others)
        advance, calls = SimSession._advance_one, [0]

        def slow_advance(self) -> None:
            calls[0] += 1
            if calls[0] % slow_every == 0:
                time.sleep(0.06)
            advance(self)

        monkeypatch.setattr(SimSession, "_advance_one", slow_advance)
    times: list[float] = []
    done = threading.Event()

    def take(snap: dict) -> None:
        if snap["status"]["state"] == "running":
            times.append(snap["t"])
            if snap["t"] >= sim_s:
                done.set()

    sess = SimSession(on_snapshot=take)
    try:
        sess.start(SortieConfig(load_scenario("cv-top-to-bottom"), speed=speed))
        assert done.wait(60.0), "the sortie did not reach the simulated time"
        sess.pause()
    finally:
        sess.close()
    return times, sess


@pytest.mark.parametrize(("speed", "slow_every"), [("1", 0), ("5", 0), ("1", 7)])
def test_paced_sortie_publishes_every_point_of_the_simulated_time_grid(
    monkeypatch, speed, slow_every
):
    """Also when some steps are slow (``slow_every``): the simulator catches up and publishes
    the grid points it passed, where a wall-clock grid skipped the slots of a late step."""
    times, sess = _fly(monkeypatch, speed, 0.5 * float(speed), slow_every)
    period_sim = sess.publish_period_s * float(speed)  # 25 ms of wall at any speed
    tick = 1.0 / 100  # the scenario's control rate
    # each snapshot is the first control tick at or after its grid point: consecutive ones are
    # the grid's period apart within one tick, none skipped, none repeated
    assert len(times) >= 0.5 * float(speed) / period_sim - 1
    assert times[0] <= tick + 1e-9  # the first control period
    for a, b in itertools.pairwise(times):
        assert math.floor(b / period_sim + 1e-9) == math.floor(a / period_sim + 1e-9) + 1, (a, b)
        assert period_sim - tick - 1e-6 <= b - a <= period_sim + tick + 1e-6, (a, b)
    assert sess.published_behind == 0


def test_behind_the_clock_only_a_starved_simulator_publishes_less(monkeypatch):
    """Within BEHIND_TOLERANCE_S, and further behind while the simulator runs at least
    BEHIND_MIN_SHARE of the ticks due (catching up after a stall), every grid point goes out;
    one that ran fewer (starved) publishes one snapshot per 1/BEHIND_PUBLISH_HZ."""
    sess = SimSession()
    try:
        sess.start(SortieConfig(load_scenario("cv-top-to-bottom"), speed="2"))
        sess.pause()
        t = sess.sim.time_s
        tol_sim = session_mod.BEHIND_TOLERANCE_S * 2.0
        due_hz = 2.0 * 100
        monkeypatch.setattr(sess, "loop_rate_hz", lambda: 1.0 * due_hz)
        assert sess._publish_gap_s(t + 0.9 * tol_sim) == 0.0
        assert sess._publish_gap_s(t + 1.5 * tol_sim) == 0.0
        monkeypatch.setattr(sess, "loop_rate_hz", lambda: 0.8 * due_hz)  # starved
        assert sess._publish_gap_s(t + 0.9 * tol_sim) == 0.0
        assert sess._publish_gap_s(t + 1.5 * tol_sim) == 1.0 / session_mod.BEHIND_PUBLISH_HZ
    finally:
        sess.close()


def test_a_simulator_slower_than_the_clock_hands_the_thread_back_to_commands(monkeypatch):
    """One paced stepping call runs at most about STEP_SLICE_S of wall, however far the clock
    is ahead, so the operator's commands (pause, reset, speed) and the stop flag are served
    while a slow simulator trails: here each step takes 20 ms and the clock is 5 s ahead."""
    sess = SimSession()
    try:
        sess.start(SortieConfig(load_scenario("cv-top-to-bottom"), speed="1"))
        sess.pause()
        advance, steps = SimSession._advance_one, [0]

        def slow_advance(self) -> None:
            steps[0] += 1
            time.sleep(0.02)
            advance(self)

        monkeypatch.setattr(SimSession, "_advance_one", slow_advance)
        now = time.perf_counter()
        sess._anchor_wall, sess._anchor_sim = now - 5.0, sess.sim.time_s
        behind = sess._step_paced(now)
        assert behind
        # STEP_SLICE_S / 20 ms = 2.5 steps; without the slice it steps the whole 5 s (500)
        assert 1 <= steps[0] <= session_mod.STEP_SLICE_S / 0.02 + 2, steps[0]
    finally:
        sess.close()
