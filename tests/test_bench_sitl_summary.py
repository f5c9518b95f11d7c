"""``groundstation bench --sitl --runs N`` summarises the runtime's targets over the runs, and the
wake-cost figure it prints times only the tick, not the sleep before it."""

from __future__ import annotations

import collections
import os

import pytest

from groundstation.bench.core import _tick_times_ms
from groundstation.bench.sitl import TARGETS_MS, summarise_runs
from groundstation.cli import main


def _flight(jitter, work, overruns, beyond):
    return {
        "jitter_p99_ms": jitter,
        "flying_tick_work_p99_ms": work,
        "overruns": overruns,
        "beyond_camera_p99_ms": beyond,
    }


def test_summary_counts_the_runs_that_meet_each_target():
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


@pytest.mark.parametrize(("flag", "expected"), [(None, None), ("on", True), ("off", False)])
def test_rehearse_reaches_each_flight(monkeypatch, flag, expected):
    """``bench --sitl --rehearse on|off`` is handed to each flight (None: the runtime's
    default) and the flight's figures to the printout."""
    import groundstation.bench.core as core
    import groundstation.bench.sitl as sitl

    asked = []
    figures = {
        **dict.fromkeys(
            (
                "jitter_p99_ms",
                "tick_work_p99_ms",
                "flying_tick_work_p99_ms",
                "beyond_camera_p99_ms",
            ),
            0.1,
        ),
        "overruns": 0,
        "rehearse": expected is not False,
        "rehearsals": 9773,
        "rehearsals_skipped": {"early tick": 213, "fusion": 2, "woken late": 2102},
        "rehearsal_median_ms": 0.13,
        "rehearsal_p99_ms": 0.35,
        "shadow_refreshes": 72,
        "rehearsal_errors": 0,
        "early_tick_work_median_ms": 0.19,
        "early_tick_work_p99_ms": 0.91,
    }

    def fly(*args):
        asked.append(args[6])  # _fly(seconds, realtime, video, foxglove, early, reserve, rehearse
        return dict(figures)

    printed = []
    monkeypatch.setattr(core, "wake_cost_ms", lambda: {})
    monkeypatch.setattr(sitl, "_fly", fly)
    monkeypatch.setattr(sitl, "_print_figures", lambda fig: printed.append(fig))
    argv = ["bench", "--sitl", "--seconds", "1"] + ([] if flag is None else ["--rehearse", flag])
    assert main(argv) == 0
    assert asked == [expected]
    assert printed[0]["rehearsals"] == 9773


@pytest.mark.parametrize(("flag", "expected"), [(None, "apart"), ("shared", "shared")])
def test_sitl_placement_reaches_each_flight(monkeypatch, flag, expected):
    """``bench --sitl --sitl-placement apart|shared`` is handed to each flight (apart by
    default) and named in the printout's first line."""
    import groundstation.bench.core as core
    import groundstation.bench.sitl as sitl

    asked = []

    def fly(*args):
        asked.append(args[7])
        return {"overruns": 0, "sitl_placement": args[7]}

    monkeypatch.setattr(core, "wake_cost_ms", lambda: {})
    monkeypatch.setattr(sitl, "_fly", fly)
    monkeypatch.setattr(sitl, "_print_figures", lambda fig: None)
    argv = ["bench", "--sitl", "--seconds", "1", "--runs", "2"]
    argv += [] if flag is None else ["--sitl-placement", flag]
    assert main(argv) == 0
    assert asked == [expected, expected]


needs_sched = pytest.mark.skipif(
    not (hasattr(os, "sched_setaffinity") and hasattr(os, "SCHED_BATCH")),
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
def test_the_sitl_placed_apart_runs_off_the_control_cpu_under_sched_batch():
    """What ``sitl_apart`` does to the SITL's process: the CPUs the onboard run does not leave
    to its control thread (all but the highest-numbered), SCHED_BATCH (a woken SITL does not
    preempt the thread that woke it); read back as the bench prints it."""
    from groundstation.bench.sitl import sitl_apart

    cpus = sorted(os.sched_getaffinity(0))
    kept = cpus[:-1] if len(cpus) > 1 else cpus
    assert _child_runs_as(sitl_apart()) == f"SCHED_BATCH on CPUs {', '.join(map(str, kept))}"
    # on one CPU, or with the onboard run's --reserve-cpu off, only the policy changes
    every = ", ".join(map(str, cpus))
    assert _child_runs_as(sitl_apart({cpus[0]})) == f"SCHED_BATCH on CPUs {every}"
    assert _child_runs_as(sitl_apart(keep_off_control=False)) == f"SCHED_BATCH on CPUs {every}"
    assert _child_runs_as(None) == f"SCHED_OTHER on CPUs {every}"


@needs_sched
def test_a_refused_placement_leaves_the_sitl_running_as_it_was():
    """CPUs this process may not use: the child is left as it was (the bench reads back and
    prints what took effect) instead of failing to start."""
    from groundstation.bench.sitl import sitl_apart

    missing = max(os.sched_getaffinity(0)) + 64
    every = ", ".join(map(str, sorted(os.sched_getaffinity(0))))
    runs_as = _child_runs_as(sitl_apart({missing, missing + 1}))
    assert runs_as == f"SCHED_OTHER on CPUs {every}"


def test_the_sitl_preexec_follows_realtime_then_the_placement(monkeypatch):
    """--realtime puts the SITL under SCHED_FIFO whatever the placement; "apart" keeps it off
    the control thread's CPU unless --reserve-cpu off; "shared" places nothing."""
    import groundstation.bench.sitl as sitl

    asked = []
    monkeypatch.setattr(sitl, "_fifo", lambda prio: ("fifo", prio))
    monkeypatch.setattr(
        sitl, "sitl_apart", lambda keep_off_control: asked.append(keep_off_control) or "apart"
    )
    assert sitl._sitl_preexec(50, "apart", None) == ("fifo", 50)
    assert sitl._sitl_preexec(50, "shared", None) == ("fifo", 50)
    assert sitl._sitl_preexec(None, "shared", None) is None
    assert sitl._sitl_preexec(None, "apart", None) == "apart"
    assert sitl._sitl_preexec(None, "apart", False) == "apart"
    assert asked == [True, False]


def test_the_first_line_names_the_sitl_placement(capsys):
    from groundstation.bench.sitl import _print_figures

    _print_figures(
        _printable(sitl_placement="apart", sitl_runs_as="SCHED_BATCH on CPUs 0", reserved_cpu=1)
    )
    out = capsys.readouterr().out
    assert "CPU 1 left to the control thread," in out  # a runtime that did not say (older)
    assert "the SITL apart (a flight controller of its own): SCHED_BATCH on CPUs 0" in out
    _print_figures(_printable(sitl_placement="shared", sitl_runs_as="SCHED_OTHER on CPUs 0, 1"))
    assert "the SITL shared (where the system puts it): SCHED_OTHER on CPUs 0, 1" in (
        capsys.readouterr().out
    )
    _print_figures(_printable(sitl_placement="SCHED_FIFO", realtime_priority=50))
    assert "the SITL under SCHED_FIFO (--realtime)" in capsys.readouterr().out


def test_the_first_line_names_how_the_bench_itself_polls(capsys):
    from groundstation.bench.sitl import _print_figures

    _print_figures(_printable(sitl_placement="apart", bench_runs_as="SCHED_IDLE"))
    assert "the bench's own polling under SCHED_IDLE" in capsys.readouterr().out
    _print_figures(_printable(sitl_placement="shared"))
    assert "the bench's own polling" not in capsys.readouterr().out


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="Linux scheduling policies")
def test_the_bench_polls_under_sched_idle_while_it_flies_and_is_put_back(monkeypatch):
    """With the SITL apart the bench's own polling (the ground station's stand-in) runs under
    SCHED_IDLE while the flight lasts and as before afterwards; not asked, or refused, it is
    left as it was and the printout says nothing."""
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
    """A flight's figures as ``_print_figures`` takes them: ``given`` and the run's frame, the
    figures a test's lines do not need absent (None)."""
    fig = collections.defaultdict(lambda: None)
    fig.update(seconds=60, camera_delay_s=0.08, load_average_1min_before_after=[0.5, 0.5])
    fig.update(given)
    return fig


def test_the_rehearsal_line_names_what_was_skipped(capsys):
    """A rehearsed flight's printout says how many rehearsals ran, how long they took, how
    many were skipped and why; the early ticks' work is printed apart."""
    from groundstation.bench.sitl import _print_figures

    fig = _printable(
        rehearse=True,
        rehearsals=9773,
        rehearsals_skipped={"early tick": 213, "fusion": 2, "woken late": 2102, "declined": 9},
        rehearsals_declined_lock_held=3,
        rehearsal_lock_waits=5,
        rehearsal_lock_wait_max_ms=0.12,
        rehearsal_median_ms=0.13,
        rehearsal_p99_ms=0.35,
        shadow_refreshes=72,
        rehearsal_errors=0,
        rehearsed_sends=9650,
        early_tick_work_median_ms=0.19,
        early_tick_work_p99_ms=0.91,
        wake_overshoot_median_ms=0.061,
        wake_overshoot_p99_ms=0.412,
        tick_work_by_kind={
            "rehearsed": {"ticks": 9773, "median_ms": 0.09, "p99_ms": 0.31, "in_slowest_1pc": 40},
            "early tick": {"ticks": 213, "median_ms": 0.19, "p99_ms": 0.91, "in_slowest_1pc": 70},
        },
    )
    _print_figures(fig)
    out = capsys.readouterr().out
    assert "ticks rehearsed" in out
    assert "9773 run, median 0.13 ms, p99 0.35 ms" in out
    assert "213 early tick, 2 fusion, 2102 woken late, 9 declined" in out
    assert "9 declined (3 of them: the loop's lock stayed taken)" in out
    assert "5 waited for the loop's lock first (at most 0.12 ms, in their times)" in out
    assert "copies taken 72, errors 0; the setpoint's send rehearsed 9650 times (to a socket" in out
    fig["rehearsed_sends"] = None  # an older runtime's figures: no word of it
    _print_figures(fig)
    assert "copies taken 72, errors 0\n" in capsys.readouterr().out
    assert "early ticks' (ticked as a fusion came in): median 0.19 ms, p99 0.91 ms" in out
    assert "ended median 0.061 ms, p99 0.412 ms after the time asked" in out
    # what the tail is made of, the kind with most of the slowest 1 % first
    assert "early tick 213, 0.19 / 0.91, 70; rehearsed 9773, 0.09 / 0.31, 40" in out


def test_the_tick_work_target_is_judged_on_the_ticks_that_flew_the_vehicle(capsys):
    """The tick-work line gives the flying ticks' figures (a setpoint sent) with the target's
    verdict, then all ticks' (with those after the sortie, sending nothing) without one; the
    send line says how much of the slowest flying ticks the send took."""
    from groundstation.bench.sitl import _print_figures

    fig = _printable(
        flying_ticks=1292,
        flying_tick_work_median_ms=0.167,
        flying_tick_work_p99_ms=0.576,
        flying_tick_work_max_ms=1.56,
        tick_work_median_ms=0.13,
        tick_work_p99_ms=0.44,
        setpoint_send_median_ms=0.043,
        setpoint_send_p99_ms=0.251,
        slowest_1pc_send_mean_ms=0.168,
        slowest_1pc_work_mean_ms=0.712,
    )
    _print_figures(fig)
    out = capsys.readouterr().out
    assert (
        "tick work, the ticks that flew the vehicle (a setpoint sent: 1292 ticks, 6.5 s): "
        "median 0.17 ms, p99 0.58 ms (max 1.56)  target <= 0.5: NOT MET" in out
    )
    assert "sending nothing): median 0.13 ms, p99 0.44 ms\n" in out  # no verdict on these
    assert (
        "median 0.043 ms, p99 0.251 ms; in the slowest 1 % of the flying ticks 0.168 of "
        "their 0.712 ms on average" in out
    )
    fig["setpoint_send_p99_ms"] = None  # an onboard run from before the send was timed
    _print_figures(fig)
    assert "the setpoint's send" not in capsys.readouterr().out


def test_the_first_line_says_whether_the_control_thread_stayed_bound(capsys):
    from groundstation.bench.sitl import _print_figures

    def first_line(**given) -> str:
        _print_figures(_printable(reserved_cpu=1, rehearse=True, **given))
        return capsys.readouterr().out.splitlines()[0]

    assert "CPU 1 left to the control thread and bound to it, ticks" in first_line(
        control_thread_bound=True, binding_escapes=0, binding_wait_max_fraction=0.01
    )
    assert (
        "CPU 1 left to the control thread and bound to it (freed 6 times while another program "
        "kept it waiting there, up to 31 % of the time), ticks"
    ) in first_line(control_thread_bound=True, binding_escapes=6, binding_wait_max_fraction=0.31)
    assert (
        "bound to it (freed 1 time while another program kept it waiting there, up to 8 % of "
        "the time; free at the end), ticks"
    ) in first_line(control_thread_bound=False, binding_escapes=1, binding_wait_max_fraction=0.08)
    assert "CPU 1 left to the control thread (not bound to it: no run delay to watch it by)," in (
        first_line(control_thread_bound=False, binding_escapes=None)
    )
    assert "CPU 1 left to the control thread, ticks" in first_line()  # an older runtime
    _print_figures(_printable(reserved_cpu=None, rehearse=True))
    assert ", no CPU reserved, ticks" in capsys.readouterr().out


def test_the_overrun_line_says_which_ticks_overran_and_how_much_was_cpu(capsys):
    from groundstation.bench.sitl import _print_figures

    _print_figures(_printable(overruns=0, scheduler_stalls=0, overran_ticks=[]))
    assert "overruns 0, stalls re-anchored 0  target 0 in 60 s: met\n" in capsys.readouterr().out
    ticks = [
        {
            "woken_as": "early tick on the camera thread",
            "at_s": 0.21,
            "work_ms": 5.31,
            "cpu_ms": 0.27,
        },
        {"woken_as": "rehearsed", "at_s": 31.0, "work_ms": 7.02, "cpu_ms": None},
    ]
    _print_figures(_printable(overruns=2, scheduler_stalls=1, overran_ticks=ticks))
    assert (
        "overruns 2, stalls re-anchored 1  target 0 in 60 s: NOT MET (early tick on the camera "
        "thread at 0.2 s: 5.31 ms, 0.27 of it CPU; rehearsed at 31.0 s: 7.02 ms)"
    ) in capsys.readouterr().out
