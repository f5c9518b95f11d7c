"""``groundstation bench --sitl``: the summary over runs, the options handed to each flight,
how the SITL and the bench itself are placed, and the printout's lines."""

from __future__ import annotations

import collections
import os

import pytest

from groundstation.bench.core import _tick_times_ms
from groundstation.bench.sitl import TARGETS_MS, summarise_runs
from groundstation.bench.sitl_report import print_figures, print_summary
from groundstation.cli import main


def _flight(jitter, work, overruns, beyond):
    return {
        "jitter_p99_ms": jitter,
        "flying_tick_work_p99_ms": work,
        "overruns": overruns,
        "beyond_camera_p99_ms": beyond,
    }


def test_summary_counts_the_runs_that_meet_each_target(capsys):
    flights = [
        _flight(0.40, 0.43, 0, 2.0),
        _flight(0.55, 0.58, 1, 2.4),
        _flight(1.20, 0.50, 0, None),  # the figure missing: not met
    ]
    s = summarise_runs(flights)
    work = s["flying_tick_work_p99_ms"]  # the ticks that flew the vehicle: the target's
    assert work["runs"] == [0.43, 0.58, 0.50]
    assert work["met"] == 2  # 0.50 <= 0.5 is met, 0.58 is not
    assert work["target_at_most"] == TARGETS_MS["tick_work_p99"]
    assert work["median"] == pytest.approx(0.50)
    assert work["worst"] == pytest.approx(0.58)
    assert s["jitter_p99_ms"]["met"] == 2 and s["jitter_p99_ms"]["worst"] == pytest.approx(1.2)
    assert s["overruns"]["met"] == 2 and s["overruns"]["worst"] == 1
    assert s["beyond_camera_p99_ms"]["met"] == 2
    assert s["beyond_camera_p99_ms"]["median"] == pytest.approx(2.2)
    assert all(row["of"] == 3 for row in s.values())
    print_summary(s)
    out = capsys.readouterr().out
    assert "period jitter p99 (ms): 0.40 / 0.55 / 1.20; median 0.55, worst 1.20" in out
    assert "beyond the camera p99 (ms): 2.00 / 2.40 / —;" in out


def test_tick_times_leave_the_sleep_before_each_tick_out():
    hot_plain, hot_fusing = _tick_times_ms(1)
    plain, fusing = _tick_times_ms(1, sleep_s=0.004)
    assert len(plain) + len(fusing) == len(hot_plain) + len(hot_fusing) > 300
    # every tick slept 4 ms first: timed with the sleep, none could take under 4 ms
    below = sum(1 for ms in plain + fusing if ms < 4.0)
    assert below > 0.9 * (len(plain) + len(fusing))


def test_runs_must_be_a_positive_count(capsys):
    with pytest.raises(SystemExit):
        main(["bench", "--sitl", "--runs", "0"])
    assert "--runs" in capsys.readouterr().err


def test_realtime_must_be_a_priority_or_off(capsys):
    for bad in ("0", "100", "fifo"):
        with pytest.raises(SystemExit):
            main(["bench", "--sitl", "--realtime", bad])
        assert "--realtime" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        ([], (None, "apart", None)),
        (["--realtime", "off", "--inject-delays", "7"], ("off", "apart", 7)),
        (["--realtime", "30", "--sitl-placement", "shared"], ("30", "shared", None)),
    ],
)
def test_the_options_reach_each_flight(monkeypatch, argv, expected):
    """``bench --sitl``'s --realtime, --sitl-placement and --inject-delays are handed to each
    flight (None: the runtime's default)."""
    import groundstation.bench.sitl as sitl
    import groundstation.bench.sitl_report as report

    asked = []

    def fly(seconds, realtime, video, foxglove, placement, inject):
        asked.append((realtime, placement, inject))
        return {"overruns": 0}

    monkeypatch.setattr(sitl, "host_wake_latency", lambda: {})
    monkeypatch.setattr(sitl, "_fly", fly)
    monkeypatch.setattr(report, "print_figures", lambda fig: None)
    assert main(["bench", "--sitl", "--seconds", "1", "--runs", "2", *argv]) == 0
    assert asked == [expected, expected]


needs_sched = pytest.mark.skipif(
    not (hasattr(os, "sched_getaffinity") and hasattr(os, "SCHED_BATCH")),
    reason="no CPU affinity or SCHED_BATCH here (not Linux)",
)


def _child_runs_as(preexec) -> str:
    """How a child process started with ``preexec`` runs (``sitl_placement_of`` it)."""
    import subprocess
    import sys

    from groundstation.bench.sitl import sitl_placement_of

    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(5)"],
                             preexec_fn=preexec)  # fmt: skip
    try:
        return sitl_placement_of(child.pid)
    finally:
        child.kill()
        child.wait()


@needs_sched
def test_the_sitl_placed_apart_runs_under_sched_batch():
    """What ``sitl_apart`` does to the SITL's process: SCHED_BATCH (a woken SITL does not
    preempt the thread that woke it), on every CPU; read back as the bench prints it."""
    from groundstation.bench.sitl import sitl_apart

    every = ", ".join(map(str, sorted(os.sched_getaffinity(0))))
    assert _child_runs_as(sitl_apart()) == f"SCHED_BATCH on CPUs {every}"
    assert _child_runs_as(None) == f"SCHED_OTHER on CPUs {every}"


def test_the_sitl_preexec_follows_realtime_then_the_placement(monkeypatch):
    """A --realtime priority puts the SITL under SCHED_FIFO whatever the placement; "apart"
    runs it under SCHED_BATCH; "shared" places nothing."""
    import groundstation.bench.sitl as sitl

    monkeypatch.setattr(sitl, "_fifo", lambda prio: ("fifo", prio))
    monkeypatch.setattr(sitl, "sitl_apart", lambda: "apart")
    assert sitl._sitl_preexec(50, "apart") == ("fifo", 50)
    assert sitl._sitl_preexec(50, "shared") == ("fifo", 50)
    assert sitl._sitl_preexec(None, "shared") is None
    assert sitl._sitl_preexec(None, "apart") == "apart"


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="Linux scheduling policies")
def test_the_bench_polls_under_sched_idle_while_it_flies_and_is_put_back(monkeypatch):
    """With the SITL apart the bench's own polling (the ground station's stand-in) runs under
    SCHED_IDLE while the flight lasts and as before afterwards; not asked, or refused, it is
    left as it was."""
    from groundstation.bench.sitl import _idle_while

    before = os.sched_getscheduler(0)
    with _idle_while(True) as runs_as:
        assert runs_as == "SCHED_IDLE" and os.sched_getscheduler(0) == os.SCHED_IDLE
    assert os.sched_getscheduler(0) == before
    with _idle_while(False) as runs_as:
        assert runs_as is None and os.sched_getscheduler(0) == before

    def refuse(*_args):
        raise PermissionError("not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with _idle_while(True) as runs_as:
        assert runs_as is None
    assert os.sched_getscheduler(0) == before


def _printable(**given) -> collections.defaultdict:
    """A flight's figures as ``print_figures`` takes them: ``given`` and the run's frame, the
    figures a test's lines do not need absent (None)."""
    fig = collections.defaultdict(lambda: None)
    fig.update(seconds=60, camera_delay_s=0.08, load_average_1min_before_after=[0.5, 0.7])
    fig.update(given)
    return fig


def test_the_first_line_says_how_the_flight_ran(capsys):
    fig = _printable(
        realtime_priority=40,
        memory_locked=True,
        control_cpus=[3],
        sitl_placement="apart",
        sitl_runs_as="SCHED_BATCH on CPUs 0, 1",
        bench_runs_as="SCHED_IDLE",
    )
    print_figures(fig)
    first = capsys.readouterr().out.splitlines()[0]
    assert (
        "control thread SCHED_FIFO 40, memory locked, on CPUs 3, the SITL apart (a flight "
        "controller of its own): SCHED_BATCH on CPUs 0, 1, the bench's own polling under "
        "SCHED_IDLE; load average 0.5 -> 0.7"
    ) in first
    print_figures(_printable(sitl_placement="shared", inject_delays=3))
    first = capsys.readouterr().out.splitlines()[0]
    assert ", normal scheduling, wake-ups delayed (--inject-delays 3), the SITL shared" in first


def test_the_timing_lines_judge_the_targets(capsys):
    """The tick-work line gives the flying ticks' figures with the target's verdict; the
    wake-up line how late the ticks started and how many missed a deadline; injected delays
    are counted apart; overran ticks are listed with their CPU share."""
    fig = _printable(
        flying_ticks=1292, flying_tick_work_median_ms=0.167, flying_tick_work_p99_ms=0.576,
        flying_tick_work_max_ms=1.56, setpoint_send_median_ms=0.043, setpoint_send_p99_ms=0.251,
        slowest_1pc_send_mean_ms=0.168, slowest_1pc_work_mean_ms=0.712,
        wake_late_median_ms=0.061, wake_late_p99_ms=0.35, wake_late_max_ms=151.2, late_ticks=4,
        missed_deadlines=37, inject_delays=1, injected_delay_s=0.41, injected_stalls=9,
        injected_freezes=1, overruns=1,
        overran_ticks=[{"at_s": 3.02, "work_ms": 5.31, "cpu_ms": 0.27}],
        sitl_result={"outcome": "HIT", "miss_m": 0.052},
    )  # fmt: skip
    print_figures(fig)
    out = capsys.readouterr().out
    assert (
        "(a setpoint sent: 1292 ticks): median 0.17 ms, p99 0.58 ms (max 1.56)  target <= 0.5: "
        "NOT MET" in out
    )
    assert "in the slowest 1 % of the flying ticks 0.168 of their 0.712 ms on average" in out
    assert (
        "wake-up after the deadline: median 0.061 ms, p99 0.350 ms, max 151.20 ms; late ticks "
        "(a deadline passed) 4, deadlines dropped 37" in out
    )
    assert "of which injected: 0.410 s in all, 9 stalls, 1 freeze" in out
    assert "overruns 1  target 0 in 60 s: NOT MET (at 3.0 s: 5.31 ms, 0.27 of it CPU)" in out
    assert "intercept: HIT, miss 0.052 m" in out
