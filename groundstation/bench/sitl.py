"""``groundstation bench --sitl``: the onboard runtime against the SITL vehicle, each flight's
figures printed (:mod:`.sitl_report`) and, over several runs, each target's per-run values."""

from __future__ import annotations

import contextlib
import json
import os
import statistics
import time
from pathlib import Path

from ..scenario import load_scenario

TARGETS_MS = {"jitter_p99": 1.0, "tick_work_p99": 0.5, "beyond_camera_p99": 5.0}
HOST_WAKE_S = 2.0  # the host's wake-up latency measured this long before the flights


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


def _fifo(priority: int):
    """A ``preexec_fn`` putting the child (all its threads) under SCHED_FIFO."""

    def set_policy() -> None:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))

    return set_policy


def sitl_apart():
    """A ``preexec_fn`` running the SITL as a flight controller of its own would run: under
    SCHED_BATCH, so that its threads, woken by a setpoint, do not preempt the thread that sent
    it (they take their fair share of the CPU); None where this system has no such policy. A
    refusal in the child leaves it as it was (:func:`sitl_placement_of` reads back what took
    effect)."""
    if not hasattr(os, "SCHED_BATCH"):
        return None

    def place() -> None:  # in the child, before exec: system calls only
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))

    return place


def sitl_placement_of(pid: int) -> str:
    """How the process ``pid`` runs, as the bench's first line says it: its policy and the
    CPUs it may use ("SCHED_BATCH on CPUs 0, 1"), or "unknown" off Linux or once it is gone."""
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


def _sitl_preexec(realtime_priority: int | None, placement: str):
    """The SITL's ``preexec_fn``: SCHED_FIFO under an explicit ``realtime_priority`` (whatever
    the placement), else :func:`sitl_apart` for "apart", else None ("shared")."""
    if realtime_priority is not None:
        return _fifo(realtime_priority)
    if placement == "apart":
        return sitl_apart()
    return None


def host_wake_latency(seconds: float = HOST_WAKE_S) -> dict:
    """This host's wake-up latency of a 5 ms periodic sleep (ms; ``onboard check-rt``'s
    measurement), at normal priority: what a tick's start waits for here besides the runtime."""
    from onboard.runtime.check_rt import percentile, wake_latencies_ms

    lat = wake_latencies_ms(seconds)
    return {
        "seconds": seconds,
        "p50_ms": percentile(lat, 0.5),
        "p99_ms": percentile(lat, 0.99),
        "max_ms": max(lat),
    }


def run_sitl_bench(
    seconds: float = 20.0,
    as_json: bool = False,
    realtime: str | None = None,
    video: bool = False,
    foxglove: bool = False,
    runs: int = 1,
    sitl_placement: str = "apart",
    inject_delays: int | None = None,
) -> int:
    """``onboard run`` against ``groundstation sitl`` on loopback, one intercept
    (cv-top-to-bottom, started as soon as the target is seen), telemetry to a ground link
    this process drains: loop rate and jitter, how late the ticks woke, tick work, overruns,
    capture-to-command latency, the onboard process's CPU share and peak memory (from /proc)
    and the intercept's outcome. The host's own wake-up latency and the load average are
    printed with the figures: the timing figures depend on the host.

    ``realtime``: ``onboard run --realtime`` (a priority, or "off"; None: the runtime's
    default); with a priority the SITL (standing in for PX4 on its own processor) runs under
    SCHED_FIFO too. ``video``: the onboard process also streams its camera (``--video``) to a
    receiver here: glass-to-glass latency. ``foxglove``: it also publishes its channels
    (``--foxglove``) to a client here subscribed to all of them. ``sitl_placement``: "apart"
    (the SITL under SCHED_BATCH and the bench's polling under SCHED_IDLE, as computers of
    their own) or "shared" (where the system puts them). ``inject_delays``: ``onboard run
    --inject-delays SEED``. ``runs``: fly that many times, print each run's figures, then each
    target's per-run values and in how many runs it was met (:func:`summarise_runs`)."""
    from .sitl_report import print_figures, print_summary

    host = host_wake_latency()
    flights = []
    for n in range(runs):
        figures = _fly(seconds, realtime, video, foxglove, sitl_placement, inject_delays)
        figures["host_wake_latency"] = host
        flights.append(figures)
        if not as_json:
            if runs > 1:
                print(f"run {n + 1} of {runs}")
            print_figures(figures)
    summary = summarise_runs(flights)
    if as_json:
        out = flights[0] if runs == 1 else {"runs": flights, "summary": summary}
        print(json.dumps(out, indent=2))
    elif runs > 1:
        print_summary(summary)
    return 0


def summarise_runs(flights: list[dict]) -> dict:
    """Per target (jitter p99, tick work p99 of the ticks that flew the vehicle, overruns,
    capture-to-command beyond the camera p99): each run's value, their median and worst, and
    in how many runs it was met (a run without the figure does not meet it)."""
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


def _free_ports(kinds: list[int]) -> list[int]:
    import socket

    socks = [socket.socket(socket.AF_INET, k) for k in kinds]
    try:
        for sock in socks:  # held together, so the ports differ
            sock.bind(("127.0.0.1", 0))
        return [sock.getsockname()[1] for sock in socks]
    finally:
        for sock in socks:
            sock.close()


def _fly(
    seconds: float,
    realtime: str | None,
    video: bool,
    foxglove: bool,
    sitl_placement: str = "apart",
    inject_delays: int | None = None,
) -> dict:
    """One flight of :func:`run_sitl_bench`: its figures (the onboard run's ``--stats`` and
    what this process measured around it)."""
    import socket
    import subprocess
    import sys
    import tempfile

    from onboard.link.px4 import MavLink

    from .sitl_foxglove import FoxgloveClient

    receiver = None
    if video:
        from ..app.video import VideoReceiver

        receiver = VideoReceiver("127.0.0.1", 0)
        receiver.start()
    kinds = [socket.SOCK_DGRAM, socket.SOCK_DGRAM, socket.SOCK_STREAM]
    fc, gcs, cam, *fox = _free_ports(kinds + [socket.SOCK_STREAM] * foxglove)
    fox_port = fox[0] if fox else None
    delay_s = load_scenario("cv-top-to-bottom").camera.delay_s
    sitl_fifo = None if realtime in (None, "off") else int(realtime)
    with tempfile.TemporaryDirectory() as tmp:
        stats_path = Path(tmp) / "stats.json"
        sitl_log = Path(tmp) / "sitl.log"
        sitl = subprocess.Popen(
            [sys.executable, "-m", "groundstation", "sitl", "cv-top-to-bottom",
             "--mavlink", f"udpin:127.0.0.1:{fc}", "--camera-port", str(cam)],
            stdout=sitl_log.open("w"), stderr=subprocess.STDOUT,
            preexec_fn=_sitl_preexec(sitl_fifo, sitl_placement),
        )  # fmt: skip
        sitl_runs_as = sitl_placement_of(sitl.pid)  # what took effect
        load_before = os.getloadavg()
        ground = MavLink(f"udpin:127.0.0.1:{gcs}", 255, 190)
        onboard = subprocess.Popen(
            [sys.executable, "-m", "onboard", "run", "--mavlink", f"udpout:127.0.0.1:{fc}",
             "--camera", f"sitl://127.0.0.1:{cam}", "--gcs", f"udpout:127.0.0.1:{gcs}",
             "--sitl-auto-start", "--duration", str(seconds), "--stats", str(stats_path),
             *([] if realtime is None else ["--realtime", realtime]),
             *([] if inject_delays is None else ["--inject-delays", str(inject_delays)]),
             *(["--video", f"127.0.0.1:{receiver.port}"] if receiver else []),
             *(["--foxglove", f"127.0.0.1:{fox_port}"] if fox_port else [])],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        fox_client = None if fox_port is None else FoxgloveClient(fox_port)
        t0 = time.perf_counter()
        cpu = peak = None
        received = 0
        apart = sitl_placement == "apart" and sitl_fifo is None
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
    cpu_s, wall_s = cpu if cpu else (None, None)
    return {
        **stats,
        "seconds": seconds,
        "load_average_1min_before_after": [load_before[0], os.getloadavg()[0]],
        "realtime": realtime,
        "inject_delays": inject_delays,
        "sitl_placement": "SCHED_FIFO" if sitl_fifo is not None else sitl_placement,
        "sitl_runs_as": sitl_runs_as,
        "bench_runs_as": bench_runs_as,
        "loop_rate_hz": stats.get("rate_hz"),
        "camera_delay_s": delay_s,
        "capture_to_command_median_ms": stats.get("latency_total_median_ms"),
        "beyond_camera_median_ms": stats.get("latency_beyond_camera_median_ms"),
        "beyond_camera_p99_ms": stats.get("latency_beyond_camera_p99_ms"),
        "after_detection_median_ms": stats.get("latency_after_detection_median_ms"),
        "after_detection_p99_ms": stats.get("latency_after_detection_p99_ms"),
        "cpu_share_of_one_core": None if cpu_s is None else cpu_s / wall_s,
        "peak_rss_mb": peak,
        "ground_messages": received,
        "sitl_result": result,
        "timesync_error_ms": timesync_error(stats, sitl_zero),
        "timesync_samples": stats.get("timesync_accepted"),
        "video": vid,
        "foxglove": None
        if fox_client is None
        else {"messages_received": fox_client.messages, **(stats.get("foxglove") or {})},
    }


def timesync_error(stats: dict, sitl_zero_monotonic_s: float | None) -> float | None:
    """The onboard TIMESYNC offset estimate minus the true offset, in ms: both processes
    count from a zero on the same monotonic clock, so the truth is the difference of the
    zeros (companion time - flight-controller time = SITL zero - onboard zero)."""
    est, zero = stats.get("timesync_offset_s"), stats.get("clock_zero_monotonic_s")
    if est is None or zero is None or sitl_zero_monotonic_s is None:
        return None
    return 1000.0 * (est - (sitl_zero_monotonic_s - zero))
