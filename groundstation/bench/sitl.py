"""``groundstation bench --sitl``: the onboard runtime against the SITL vehicle."""

from __future__ import annotations

import contextlib
import json
import os
import statistics
import time
from pathlib import Path

from ..scenario import load_scenario


def _overran(ticks: list[dict] | None) -> str:
    """The overran ticks: how each was woken, when (s after the first tick), its work and how
    much of it was the ticking thread's CPU (the rest: waiting for the GIL, the CPU or the
    host)."""
    if not ticks:
        return ""

    def one(t: dict) -> str:
        cpu = "" if t["cpu_ms"] is None else f", {t['cpu_ms']:.2f} of it CPU"
        return f"{t['woken_as']} at {t['at_s']:.1f} s: {t['work_ms']:.2f} ms{cpu}"

    return " (" + "; ".join(one(t) for t in ticks) + ")"


def _rehearsed_sends(n: int | None) -> str:
    """The rehearsals whose setpoint frame went to the runtime's own socket (the system call
    and the kernel's UDP and IP layers warmed for the real send; none where the link to PX4 is
    not UDP)."""
    if n is None:
        return ""
    return f"; the setpoint's send rehearsed {n} times (to a socket of its own, never to PX4)"


def _lock_held(n: int | None) -> str:
    """The part of the declined rehearsals whose loop's lock stayed taken (another thread's
    batch ran into the wake-up); the rest had nothing to rehearse on yet."""
    return "" if not n else f" ({n} of them: the loop's lock stayed taken)"


def _lock_waits(n: int | None, max_ms: float | None) -> str:
    """The rehearsals that waited for another thread's batch to let the loop's lock go (their
    times above include the wait)."""
    if not n:
        return ""
    return f"; {n} waited for the loop's lock first (at most {max_ms:.2f} ms, in their times)"


def _proc_cpu_s(pid: int) -> float | None:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _proc_peak_rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


TARGETS_MS = {"jitter_p99": 1.0, "tick_work_p99": 0.5, "beyond_camera_p99": 5.0}


def _fifo(priority: int):
    """A ``preexec_fn`` putting the child (all its threads) under SCHED_FIFO."""

    def set_policy() -> None:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))

    return set_policy


def sitl_apart(cpus: set[int] | None = None, keep_off_control: bool = True):
    """A ``preexec_fn`` placing the SITL as a flight controller of its own would be, or None
    where this system has no such calls (not Linux): under SCHED_BATCH, so that its threads,
    woken by a setpoint, do not preempt the thread that sent it (the scheduler's tick still
    may; they take their fair share of the CPU), and with ``keep_off_control`` on the CPUs
    ``onboard run --reserve-cpu on`` does not leave to its control thread (``split_cpus`` of
    ``cpus``, by default this process's; nothing to keep it off on one CPU). A refusal in the
    child leaves it as it was (:func:`sitl_placement_of` reads back what took effect)."""
    from onboard.runtime.scheduler import split_cpus

    if not (hasattr(os, "sched_setaffinity") and hasattr(os, "SCHED_BATCH")):
        return None
    split = split_cpus(os.sched_getaffinity(0) if cpus is None else cpus)
    others = split[1] if split is not None and keep_off_control else None

    def place() -> None:  # in the child, before exec: system calls only
        try:
            if others is not None:
                os.sched_setaffinity(0, others)
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
        except OSError:
            pass

    return place


def sitl_placement_of(pid: int) -> str:
    """How the process ``pid`` runs, as the bench's first line says it: its policy and the
    CPUs it may use ("SCHED_BATCH on CPUs 0"), or "unknown" off Linux or once it is gone."""
    names = {
        getattr(os, n): n for n in ("SCHED_OTHER", "SCHED_BATCH", "SCHED_FIFO", "SCHED_IDLE")
        if hasattr(os, n)
    }  # fmt: skip
    try:
        policy = names.get(os.sched_getscheduler(pid), "another policy")
        cpus = ", ".join(str(c) for c in sorted(os.sched_getaffinity(pid)))
    except (AttributeError, OSError):
        return "unknown"
    return f"{policy} on CPUs {cpus}"


@contextlib.contextmanager
def _idle_while(enabled: bool):
    """This thread (the bench's own polling: the ground station's stand-in, another computer
    on the vehicle) under SCHED_IDLE for the block, so a control thread woken on its CPU runs
    at once instead of waiting for it; put back after. Yields how it ran ("SCHED_IDLE"), or
    None when not asked or refused."""
    before = None
    if enabled and hasattr(os, "SCHED_IDLE"):
        try:
            was = os.sched_getscheduler(0), os.sched_getparam(0)
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
            before = was
        except OSError:
            pass
    try:
        yield None if before is None else "SCHED_IDLE"
    finally:
        if before is not None:
            with contextlib.suppress(OSError):
                os.sched_setscheduler(0, before[0], before[1])


def _sitl_preexec(realtime_priority: int | None, placement: str, reserve_cpu: bool | None):
    """The SITL's ``preexec_fn``: SCHED_FIFO under ``realtime_priority`` (whatever the
    placement), else :func:`sitl_apart` for "apart" (kept off the control thread's CPU unless
    ``onboard run --reserve-cpu off``), else None ("shared")."""
    if realtime_priority is not None:
        return _fifo(realtime_priority)
    if placement == "apart":
        return sitl_apart(keep_off_control=reserve_cpu is not False)
    return None


def run_sitl_bench(
    seconds: float = 20.0,
    as_json: bool = False,
    realtime_priority: int | None = None,
    video: bool = False,
    foxglove: bool = False,
    early_tick: bool | None = None,
    reserve_cpu: bool | None = None,
    runs: int = 1,
    rehearse: bool | None = None,
    sitl_placement: str = "apart",
) -> int:
    """``onboard run`` against ``groundstation sitl`` on loopback, one intercept
    (cv-top-to-bottom, started as soon as the target is seen), telemetry to a ground link
    this process drains: loop rate and jitter, capture-to-command latency, and the onboard
    process's CPU share and peak memory (from /proc). With ``realtime_priority`` the onboard
    runtime runs with ``--realtime`` and the SITL (standing in for PX4 on its own processor)
    under SCHED_FIFO too. The load average is printed with the figures: the machine is
    shared, and so is what sleeping between ticks costs a tick on it (:func:`wake_cost_ms`,
    measured first). ``video``: the onboard process also streams its camera (``--video``) to a
    receiver here (:mod:`groundstation.app.video`): glass-to-glass latency, from the SITL
    camera's capture to the decoded frame. ``foxglove``: the onboard process also publishes
    its channels (``--foxglove``) to a Foxglove WebSocket client here subscribed to all of
    them: what that costs the control tick. ``early_tick``: ``onboard run --early-tick on``
    or ``off`` (None: the runtime's default); ``reserve_cpu`` likewise ``--reserve-cpu``,
    ``rehearse`` ``--rehearse``. ``sitl_placement``: "apart" (default; :func:`sitl_apart`:
    the SITL off the control thread's CPU, its wake-ups not preempting the onboard run's
    threads, as a flight controller of its own) or "shared" (where the system puts it: its
    thread, woken by a setpoint, then often preempted the thread that sent it; README
    "Session 18"). Under ``realtime_priority`` the SITL runs under SCHED_FIFO instead.
    ``runs``: fly that many times, print each run's figures, then each target's per-run
    values and in how many runs it was met (:func:`summarise_runs`)."""
    from .core import wake_cost_ms

    host = wake_cost_ms()
    flights = []
    for n in range(runs):
        figures = _fly(
            seconds, realtime_priority, video, foxglove, early_tick, reserve_cpu, rehearse,
            sitl_placement,
        )  # fmt: skip
        figures["host_wake_cost"] = host
        flights.append(figures)
        if not as_json:
            if runs > 1:
                print(f"run {n + 1} of {runs}")
            _print_figures(figures)
    summary = summarise_runs(flights)
    if as_json:
        out = flights[0] if runs == 1 else {"runs": flights, "summary": summary}
        print(json.dumps(out, indent=2))
    elif runs > 1:
        _print_summary(summary)
    return 0


def summarise_runs(flights: list[dict]) -> dict:
    """Per target of #16 (jitter p99, tick work p99 of the ticks that flew the vehicle,
    overruns, capture-to-command beyond the camera p99): each run's value, their median and
    worst, and in how many runs it was met (a run without the figure does not meet it)."""
    targets = {
        "jitter_p99_ms": TARGETS_MS["jitter_p99"],
        "flying_tick_work_p99_ms": TARGETS_MS["tick_work_p99"],
        "overruns": 0,
        "beyond_camera_p99_ms": TARGETS_MS["beyond_camera_p99"],
    }
    out = {}
    for key, target in targets.items():
        values = [f.get(key) for f in flights]
        known = sorted(v for v in values if v is not None)
        out[key] = {
            "target_at_most": target,
            "runs": values,
            "median": statistics.median(known) if known else None,
            "worst": known[-1] if known else None,
            "met": sum(1 for v in values if v is not None and v <= target),
            "of": len(values),
        }
    return out


def _print_summary(summary: dict) -> None:
    print(f"over {next(iter(summary.values()))['of']} runs (a target is met in a run when that "
          "run's figure meets it):")  # fmt: skip
    names = {
        "jitter_p99_ms": "period jitter p99 (ms)",
        "flying_tick_work_p99_ms": "tick work p99, the ticks that flew the vehicle (ms)",
        "overruns": "overruns",
        "beyond_camera_p99_ms": "capture-to-command beyond the camera p99 (ms)",
    }
    for key, row in summary.items():
        digits = "g" if key == "overruns" else ".2f"

        def fmt(v, digits=digits) -> str:
            return "—" if v is None else format(v, digits)

        vals = " ".join(fmt(v) for v in row["runs"])
        med, worst = row["median"], row["worst"]
        print(
            f"  {names[key]}: {vals}; median {fmt(med)}, worst {fmt(worst)}; target <= "
            f"{row['target_at_most']:g} met in {row['met']} of {row['of']}"
        )


def _fly(
    seconds: float,
    realtime_priority: int | None,
    video: bool,
    foxglove: bool,
    early_tick: bool | None,
    reserve_cpu: bool | None,
    rehearse: bool | None = None,
    sitl_placement: str = "apart",
) -> dict:
    """One flight of :func:`run_sitl_bench`: its figures."""
    import socket
    import subprocess
    import sys
    import tempfile

    from onboard.link.px4 import MavLink

    receiver = None
    if video:
        from ..app.video import VideoReceiver

        receiver = VideoReceiver("127.0.0.1", 0)
        receiver.start()
    socks = [socket.socket(socket.AF_INET, k) for k in (socket.SOCK_DGRAM,) * 2]
    socks.append(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
    for sock in socks:  # held together, so the three ports differ
        sock.bind(("127.0.0.1", 0))
    fc, gcs, cam = (sock.getsockname()[1] for sock in socks)
    fox_port = None
    if foxglove:
        socks.append(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
        socks[-1].bind(("127.0.0.1", 0))
        fox_port = socks[-1].getsockname()[1]
    for sock in socks:
        sock.close()
    delay_s = load_scenario("cv-top-to-bottom").camera.delay_s
    with tempfile.TemporaryDirectory() as tmp:
        stats_path = Path(tmp) / "stats.json"
        sitl_log = Path(tmp) / "sitl.log"
        sitl = subprocess.Popen(
            [sys.executable, "-m", "groundstation", "sitl", "cv-top-to-bottom",
             "--mavlink", f"udpin:127.0.0.1:{fc}", "--camera-port", str(cam)],
            stdout=sitl_log.open("w"), stderr=subprocess.STDOUT,
            preexec_fn=_sitl_preexec(realtime_priority, sitl_placement, reserve_cpu),
        )  # fmt: skip
        sitl_runs_as = sitl_placement_of(sitl.pid)  # what took effect
        rt_args = [] if realtime_priority is None else ["--realtime", str(realtime_priority)]
        load_before = os.getloadavg()
        ground = MavLink(f"udpin:127.0.0.1:{gcs}", 255, 190)
        onboard = subprocess.Popen(
            [sys.executable, "-m", "onboard", "run", "--mavlink", f"udpout:127.0.0.1:{fc}",
             "--camera", f"sitl://127.0.0.1:{cam}", "--gcs", f"udpout:127.0.0.1:{gcs}",
             "--sitl-auto-start", "--duration", str(seconds), "--stats", str(stats_path),
             *rt_args,
             *([] if early_tick is None else ["--early-tick", "on" if early_tick else "off"]),
             *([] if reserve_cpu is None else ["--reserve-cpu", "on" if reserve_cpu else "off"]),
             *([] if rehearse is None else ["--rehearse", "on" if rehearse else "off"]),
             *(["--video", f"127.0.0.1:{receiver.port}"] if receiver else []),
             *(["--foxglove", f"127.0.0.1:{fox_port}"] if fox_port else [])],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        fox_client = None if fox_port is None else _FoxgloveClient(fox_port)
        t0 = time.perf_counter()
        cpu = peak = None
        received = 0
        # with the SITL apart, the bench's own polling is the ground station's stand-in, on a
        # computer of its own on the vehicle too (README "What bench --sitl judges the tick on")
        apart = sitl_placement == "apart" and realtime_priority is None
        with _idle_while(apart) as bench_runs_as:
            while onboard.poll() is None:
                received += len(ground.poll())
                c, m = _proc_cpu_s(onboard.pid), _proc_peak_rss_mb(onboard.pid)
                wall = time.perf_counter() - t0
                cpu, peak = (c, wall) if c is not None else cpu, m if m is not None else peak
                time.sleep(0.05)
        sitl.terminate()
        sitl.wait(10)
        ground.close()
        if fox_client is not None:
            fox_client.stop()
        stats = json.loads(stats_path.read_text()) if stats_path.exists() else {}
        result = sitl_zero = None
        for line in sitl_log.read_text().splitlines():
            if line.startswith("SITL_RESULT "):
                result = json.loads(line.removeprefix("SITL_RESULT "))
            elif line.startswith("sitl: boot clock zero at monotonic "):
                sitl_zero = float(line.split()[-2])
    vid = None
    if receiver is not None:
        receiver.stop()
        vid = receiver.stats()
        vid["fps"] = receiver.frames / seconds
        lat = vid["latency_median_ms"]
        vid["beyond_camera_median_ms"] = None if lat is None else lat - 1000 * delay_s
    timesync_error_ms = timesync_error(stats, sitl_zero)
    cpu_s, wall_s = cpu if cpu else (None, None)
    figures = {
        "seconds": seconds,
        "load_average_1min_before_after": [load_before[0], os.getloadavg()[0]],
        "realtime_priority": realtime_priority,
        "early_tick": stats.get("early_tick"),
        "reserved_cpu": stats.get("reserved_cpu"),
        "control_thread_bound": stats.get("control_thread_bound"),
        "binding_escapes": stats.get("binding_escapes"),
        "binding_wait_max_fraction": stats.get("binding_wait_max_fraction"),
        "rehearse": stats.get("rehearse"),
        "sitl_placement": "SCHED_FIFO" if realtime_priority is not None else sitl_placement,
        "sitl_runs_as": sitl_runs_as,
        "bench_runs_as": bench_runs_as,
        "rehearsals": stats.get("rehearsals"),
        "rehearsals_skipped": stats.get("rehearsals_skipped"),
        "rehearsals_declined_lock_held": stats.get("rehearsals_declined_lock_held"),
        "rehearsal_lock_waits": stats.get("rehearsal_lock_waits"),
        "rehearsal_lock_wait_max_ms": stats.get("rehearsal_lock_wait_max_ms"),
        "rehearsal_median_ms": stats.get("rehearsal_median_ms"),
        "wake_overshoot_median_ms": stats.get("wake_overshoot_median_ms"),
        "wake_overshoot_p99_ms": stats.get("wake_overshoot_p99_ms"),
        "rehearsal_p99_ms": stats.get("rehearsal_p99_ms"),
        "shadow_refreshes": stats.get("shadow_refreshes"),
        "rehearsal_errors": stats.get("rehearsal_errors"),
        "rehearsed_sends": stats.get("rehearsed_sends"),
        "scheduler_stalls": stats.get("scheduler_stalls"),
        "loop_rate_hz": stats.get("rate_hz"),
        "jitter_p99_ms": stats.get("jitter_p99_ms"),
        "jitter_max_ms": stats.get("jitter_max_ms"),
        "tick_work_median_ms": stats.get("tick_work_median_ms"),
        "tick_work_p99_ms": stats.get("tick_work_p99_ms"),
        "early_tick_work_median_ms": stats.get("early_tick_work_median_ms"),
        "early_tick_work_p99_ms": stats.get("early_tick_work_p99_ms"),
        "tick_work_by_kind": stats.get("tick_work_by_kind"),
        "tick_cpu_median_ms": stats.get("tick_cpu_median_ms"),
        "tick_cpu_p99_ms": stats.get("tick_cpu_p99_ms"),
        "flying_ticks": stats.get("flying_ticks"),
        "flying_tick_work_median_ms": stats.get("flying_tick_work_median_ms"),
        "flying_tick_work_p99_ms": stats.get("flying_tick_work_p99_ms"),
        "flying_tick_work_max_ms": stats.get("flying_tick_work_max_ms"),
        "setpoint_send_median_ms": stats.get("setpoint_send_median_ms"),
        "setpoint_send_p99_ms": stats.get("setpoint_send_p99_ms"),
        "slowest_1pc_work_mean_ms": stats.get("slowest_1pc_work_mean_ms"),
        "slowest_1pc_send_mean_ms": stats.get("slowest_1pc_send_mean_ms"),
        "overruns": stats.get("overruns"),
        "overran_ticks": stats.get("overran_ticks"),
        "attitude_jumps": stats.get("attitude_jumps"),
        "stale_attitude_ticks": stats.get("stale_attitude_ticks"),
        "early_ticks": stats.get("early_ticks"),
        "early_ticks_on_camera_thread": stats.get("early_ticks_on_camera_thread"),
        "early_gap_median_ms": stats.get("early_gap_median_ms"),
        "ticks": stats.get("ticks"),
        "lock_wait_p99_ms": stats.get("lock_wait_p99_ms"),
        "lock_wait_max_ms": stats.get("lock_wait_max_ms"),
        "ticks_waiting_for_a_fusion": stats.get("ticks_waiting_for_a_fusion"),
        "fusion_wait_max_ms": stats.get("fusion_wait_max_ms"),
        "camera_delay_s": delay_s,
        "capture_to_command_median_ms": stats.get("latency_total_median_ms"),
        "beyond_camera_median_ms": stats.get("latency_beyond_camera_median_ms"),
        "beyond_camera_p99_ms": stats.get("latency_beyond_camera_p99_ms"),
        "after_detection_median_ms": stats.get("latency_after_detection_median_ms"),
        "after_detection_p99_ms": stats.get("latency_after_detection_p99_ms"),
        "detections_fused": stats.get("detections_fused"),
        "cpu_share_of_one_core": None if cpu_s is None else cpu_s / wall_s,
        "peak_rss_mb": peak,
        "ground_messages": received,
        "sitl_result": result,
        "timesync_error_ms": timesync_error_ms,
        "timesync_min_rtt_ms": stats.get("timesync_min_rtt_ms"),
        "timesync_samples": stats.get("timesync_accepted"),
        "video": vid,
        "foxglove": None
        if fox_client is None
        else {"messages_received": fox_client.messages, **(stats.get("foxglove") or {})},
    }
    return figures


def _print_figures(figures: dict) -> None:
    from onboard.runtime.runner import RuntimeConfig

    seconds, realtime_priority = figures["seconds"], figures["realtime_priority"]
    delay_s, peak = figures["camera_delay_s"], figures["peak_rss_mb"]
    cpu_share, timesync_error_ms = figures["cpu_share_of_one_core"], figures["timesync_error_ms"]
    vid, result = figures["video"], figures["sitl_result"]

    def f(x, d=2):
        return "—" if x is None else f"{x:.{d}f}"

    def verdict(value, target: float) -> str:
        ok = value is not None and value <= target
        return f"  target <= {target:g}: {'met' if ok else 'NOT MET'}"

    la = figures["load_average_1min_before_after"]
    rt = "" if realtime_priority is None else f", SCHED_FIFO {realtime_priority}"
    rt += {True: ", early tick on", False: ", early tick off"}.get(figures["early_tick"], "")
    cpu = figures["reserved_cpu"]
    rt += ", no CPU reserved" if cpu is None else f", CPU {cpu} left to the control thread"
    escapes = figures.get("binding_escapes")
    if cpu is not None and escapes is not None:
        rt += " and bound to it"
        if escapes:
            waited = figures.get("binding_wait_max_fraction")
            rt += (
                f" (freed {escapes} time{'s' * (escapes != 1)} while another program kept it"
                " waiting there"
                + ("" if waited is None else f", up to {100 * waited:.0f} % of the time")
                + ("; free at the end" if figures["control_thread_bound"] is False else "")
                + ")"
            )
    elif cpu is not None and figures.get("control_thread_bound") is False:
        rt += " (not bound to it: no run delay to watch it by)"
    rt += {True: ", ticks rehearsed", False: ", no rehearsal"}.get(figures.get("rehearse"), "")
    placement = {
        "apart": "apart (a flight controller of its own)",
        "shared": "shared (where the system puts it)",
        "SCHED_FIFO": "under SCHED_FIFO (--realtime)",
    }.get(figures.get("sitl_placement"))
    if placement is not None:
        runs_as = figures.get("sitl_runs_as")
        rt += f", the SITL {placement}" + ("" if runs_as is None else f": {runs_as}")
    if figures.get("bench_runs_as") is not None:
        rt += f", the bench's own polling under {figures['bench_runs_as']}"
    print(
        f"onboard run vs groundstation sitl, {seconds:g} s, one cv-top-to-bottom intercept"
        f"{rt}; load average {la[0]:.1f} -> {la[1]:.1f} on {os.cpu_count()} CPUs"
    )
    print(
        f"  loop rate {f(figures['loop_rate_hz'], 1)} Hz  target {RuntimeConfig.control_rate_hz:g}"
    )
    if figures["early_ticks"] is not None:
        print(
            f"  early ticks (a detection fused, the grid re-anchored) {figures['early_ticks']}, "
            f"median {f(figures['early_gap_median_ms'])} ms after the previous tick (not counted "
            "in the rate and jitter)"
            + (
                ""
                if figures.get("early_ticks_on_camera_thread") is None
                else f"; {figures['early_ticks_on_camera_thread']} of them ticked on the camera "
                "thread as it fused, the others by the control thread, awake already"
            )
        )
    print(
        f"  period jitter p99 {f(figures['jitter_p99_ms'])} ms (max {f(figures['jitter_max_ms'])})"
        + verdict(figures["jitter_p99_ms"], TARGETS_MS["jitter_p99"])
    )
    period_s = 1.0 / RuntimeConfig.control_rate_hz  # the onboard run's default, flown here
    flying = figures.get("flying_ticks")
    print(
        f"  tick work, the ticks that flew the vehicle (a setpoint sent: "
        f"{'—' if flying is None else flying} ticks, "
        f"{'—' if flying is None else format(flying * period_s, '.1f')} s): median "
        f"{f(figures.get('flying_tick_work_median_ms'))} ms, p99 "
        f"{f(figures.get('flying_tick_work_p99_ms'))} ms (max "
        f"{f(figures.get('flying_tick_work_max_ms'))})"
        + verdict(figures.get("flying_tick_work_p99_ms"), TARGETS_MS["tick_work_p99"])
    )
    if figures.get("setpoint_send_p99_ms") is not None:
        print(
            f"    of which the setpoint's send (packed, then one system call that delivers it on "
            f"loopback and wakes the SITL): median "
            f"{f(figures['setpoint_send_median_ms'], 3)} ms, p99 "
            f"{f(figures['setpoint_send_p99_ms'], 3)} ms; in the slowest 1 % of the flying ticks "
            f"{f(figures['slowest_1pc_send_mean_ms'], 3)} of their "
            f"{f(figures['slowest_1pc_work_mean_ms'], 3)} ms on average"
        )
    print(
        f"    all ticks, with those before the start and after the end (the loop runs on, "
        f"sending nothing): median {f(figures['tick_work_median_ms'])} ms, p99 "
        f"{f(figures['tick_work_p99_ms'])} ms"
    )
    print(
        f"    all ticks' CPU time (the ticking thread's): median {f(figures['tick_cpu_median_ms'])}"
        f" ms, p99 {f(figures['tick_cpu_p99_ms'])} ms (the rest waits for the GIL or the CPU)"
    )
    if figures.get("early_tick_work_median_ms") is not None:
        print(
            f"    of which the early ticks' (ticked as a fusion came in): median "
            f"{f(figures['early_tick_work_median_ms'])} ms, p99 "
            f"{f(figures['early_tick_work_p99_ms'])} ms"
        )
    if figures["lock_wait_p99_ms"] is not None:
        print(
            f"    of which waiting for the loop's lock: p99 {f(figures['lock_wait_p99_ms'])} ms"
            f" (max {f(figures['lock_wait_max_ms'])}); ticks that waited (asleep, before they "
            f"started) for a fusion to end: {figures['ticks_waiting_for_a_fusion']} (at most "
            f"{f(figures['fusion_wait_max_ms'])} ms past the deadline)"
        )
    if figures.get("rehearse"):
        skipped = figures["rehearsals_skipped"] or {}
        print(
            f"    before it (not in it), the rehearsal on a copy of the loop: "
            f"{figures['rehearsals']} run, median {f(figures['rehearsal_median_ms'])} ms, p99 "
            f"{f(figures['rehearsal_p99_ms'])} ms; not rehearsed: "
            + ", ".join(f"{n} {why}" for why, n in skipped.items())
            + _lock_held(figures.get("rehearsals_declined_lock_held"))
            + _lock_waits(
                figures.get("rehearsal_lock_waits"), figures.get("rehearsal_lock_wait_max_ms")
            )
            + f"; copies taken {figures['shadow_refreshes']}, errors {figures['rehearsal_errors']}"
            + _rehearsed_sends(figures.get("rehearsed_sends"))
        )
    if figures.get("wake_overshoot_p99_ms") is not None:
        print(
            f"    the sleep before a grid tick ended median "
            f"{f(figures['wake_overshoot_median_ms'], 3)} ms, p99 "
            f"{f(figures['wake_overshoot_p99_ms'], 3)} ms after the time asked (the kernel's "
            "and the host's wake-up delay; later than the rehearsal's lead: woken late)"
        )
    by_kind = figures.get("tick_work_by_kind")
    if by_kind:
        slowest = sorted(by_kind.items(), key=lambda kv: -kv[1]["in_slowest_1pc"])
        print(
            "    all ticks by how the tick was woken (ticks, median / p99 ms, of the slowest 1 %): "
            + "; ".join(
                f"{kind} {v['ticks']}, {f(v['median_ms'])} / {f(v['p99_ms'])}, "
                f"{v['in_slowest_1pc']}"
                for kind, v in slowest
            )
        )
    print(
        f"  overruns {figures['overruns']}, stalls re-anchored {figures['scheduler_stalls']}"
        f"  target 0 in {seconds:g} s: {'met' if figures['overruns'] == 0 else 'NOT MET'}"
        + _overran(figures.get("overran_ticks"))
    )
    print(
        f"    LOS changes re-based through the gyro: attitude jumps (a stale attitude replaced) "
        f"{figures['attitude_jumps']}, ticks with a stale attitude "
        f"{figures['stale_attitude_ticks']}"
    )
    print(
        f"  capture-to-command median {f(figures['capture_to_command_median_ms'], 1)} ms, of "
        f"which beyond the camera's own delay ({1000 * delay_s:.0f} ms): median "
        f"{f(figures['beyond_camera_median_ms'])} ms, p99 {f(figures['beyond_camera_p99_ms'])} ms"
        + verdict(figures["beyond_camera_p99_ms"], TARGETS_MS["beyond_camera_p99"])
    )
    print(
        f"    of which from the detector's result to the command: median "
        f"{f(figures['after_detection_median_ms'])} ms, p99 {f(figures['after_detection_p99_ms'])}"
        " ms (the rest is the camera thread: frame transfer and detection)"
    )
    print(
        f"  onboard process: CPU {f(None if cpu_share is None else 100 * cpu_share, 0)}"
        f" % of one core, peak memory {f(peak, 0)} MB  target <= 300 MB"
    )
    print(
        f"  TIMESYNC offset error {f(timesync_error_ms, 3)} ms (quickest round trip "
        f"{f(figures['timesync_min_rtt_ms'], 3)} ms, {figures['timesync_samples']} samples)"
    )
    if vid is not None:
        print(
            f"  video (H.264/RTP, decoded here): {vid['frames']} frames ({f(vid['fps'], 1)}/s), "
            f"glass-to-glass median {f(vid['latency_median_ms'], 1)} ms, p95 "
            f"{f(vid['latency_p95_ms'], 1)} ms, of which the camera's own delay "
            f"{1000 * delay_s:.0f} ms; {vid['packets_lost']} packets lost"
        )
    fox = figures["foxglove"]
    if fox is not None:
        print(
            f"  Foxglove live: {fox['messages_received']} messages received here (every channel "
            f"subscribed), {fox.get('published_frames')} frames published, "
            f"{fox.get('dropped')} dropped by the control thread's queue; the publishing "
            f"thread's CPU {f(1000 * fox['cpu_s'] / seconds if fox.get('cpu_s') else None, 1)}"
            " ms per second"
        )
    if result:
        print(f"  intercept: {result['outcome']}, miss {result['miss_m']:.3f} m")
    host = figures.get("host_wake_cost")
    if host is not None:
        print(
            f"  this machine: the loop's tick (a simulated sortie) median "
            f"{f(host['back_to_back_median_ms'], 3)} ms back to back, "
            f"{f(host['after_sleep_median_ms'], 3)} ms (p99 {f(host['after_sleep_p99_ms'], 3)}) "
            f"after a {host['sleep_ms']:g} ms sleep ({f(host['ratio_of_medians'], 1)}x): what "
            "sleeping between ticks costs a tick here"
        )


class _FoxgloveClient:
    """A Foxglove WebSocket client in a thread: connects (retrying while ``onboard run``
    starts), subscribes to every advertised channel and counts the messages."""

    def __init__(self, port: int) -> None:
        import threading

        self.port = port
        self.messages = 0
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._run, name="foxglove-client", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from websockets.sync.client import connect

        while not self._halt.is_set():
            try:
                ws = connect(f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"])
                break
            except OSError:
                self._halt.wait(0.2)
        else:
            return
        with ws:
            subscribed = 0
            while not self._halt.is_set():
                try:
                    data = ws.recv(timeout=0.2)
                except TimeoutError:
                    continue
                except Exception:  # the server stopped
                    return
                if isinstance(data, bytes):
                    self.messages += 1
                    continue
                msg = json.loads(data)
                if msg.get("op") == "advertise":
                    subs = [
                        {"id": subscribed + k, "channelId": c["id"]}
                        for k, c in enumerate(msg["channels"])
                    ]
                    subscribed += len(subs)
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def stop(self) -> None:
        self._halt.set()
        self._thread.join(timeout=2)


def timesync_error(stats: dict, sitl_zero_monotonic_s: float | None) -> float | None:
    """The onboard TIMESYNC offset estimate minus the true offset, in ms: both processes
    count from a zero on the same monotonic clock, so the truth is the difference of the
    zeros (companion time - flight-controller time = SITL zero - onboard zero)."""
    est, zero = stats.get("timesync_offset_s"), stats.get("clock_zero_monotonic_s")
    if est is None or zero is None or sitl_zero_monotonic_s is None:
        return None
    return 1000.0 * (est - (sitl_zero_monotonic_s - zero))
