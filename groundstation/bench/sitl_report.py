"""``groundstation bench --sitl``'s printout: one flight's figures, and the targets over
several runs. The timing figures (jitter, wake-up lateness, tick work, overruns, the latency
beyond the camera) depend on the host: its kernel, its load, whether the control thread got
SCHED_FIFO; the outcome, the miss and the TIMESYNC error should not."""

from __future__ import annotations

import os

from .sitl import TARGETS_MS

_NAMES = {
    "jitter_p99_ms": "period jitter p99 (ms)",
    "flying_tick_work_p99_ms": "tick work p99, the ticks that flew the vehicle (ms)",
    "overruns": "overruns",
    "beyond_camera_p99_ms": "capture-to-command beyond the camera p99 (ms)",
}


def _f(x, d: int = 2) -> str:
    return "—" if x is None else f"{x:.{d}f}"


def _verdict(value, target: float) -> str:
    ok = value is not None and value <= target
    return f"  target <= {target:g}: {'met' if ok else 'NOT MET'}"


def _overran(ticks: list[dict] | None) -> str:
    """The overran ticks: when (s after the first tick), their work and how much of it was the
    ticking thread's CPU (the rest: waiting for the CPU, a lock or the host)."""
    if not ticks:
        return ""

    def one(t: dict) -> str:
        cpu = "" if t["cpu_ms"] is None else f", {t['cpu_ms']:.2f} of it CPU"
        return f"at {t['at_s']:.1f} s: {t['work_ms']:.2f} ms{cpu}"

    return " (" + "; ".join(one(t) for t in ticks) + ")"


def _first_line(fig: dict) -> str:
    """How the flight ran: the control thread's scheduling, the SITL's and the bench's."""
    prio = fig.get("realtime_priority")
    how = f", control thread SCHED_FIFO {prio}" if prio is not None else ", normal scheduling"
    if fig.get("memory_locked"):
        how += ", memory locked"
    if fig.get("control_cpus"):
        how += ", on CPUs " + ", ".join(map(str, fig["control_cpus"]))
    if fig.get("inject_delays") is not None:
        how += f", wake-ups delayed (--inject-delays {fig['inject_delays']})"
    placement = {
        "apart": "apart (a flight controller of its own)",
        "shared": "shared (where the system puts it)",
        "SCHED_FIFO": "under SCHED_FIFO (--realtime)",
    }.get(fig.get("sitl_placement"))
    if placement is not None:
        runs_as = fig.get("sitl_runs_as")
        how += f", the SITL {placement}" + ("" if runs_as is None else f": {runs_as}")
    if fig.get("bench_runs_as") is not None:
        how += f", the bench's own polling under {fig['bench_runs_as']}"
    la = fig["load_average_1min_before_after"]
    return (
        f"onboard run vs groundstation sitl, {fig['seconds']:g} s, one cv-top-to-bottom "
        f"intercept{how}; load average {la[0]:.1f} -> {la[1]:.1f} on {os.cpu_count()} CPUs"
    )


def print_figures(fig: dict) -> None:
    """One flight's figures (:func:`groundstation.bench.sitl._fly`)."""
    delay_s, seconds = fig["camera_delay_s"], fig["seconds"]
    print(_first_line(fig))
    print(f"  loop rate {_f(fig.get('loop_rate_hz'), 1)} Hz")
    print(
        f"  period jitter p99 {_f(fig.get('jitter_p99_ms'))} ms "
        f"(max {_f(fig.get('jitter_max_ms'))})"
        + _verdict(fig.get("jitter_p99_ms"), TARGETS_MS["jitter_p99"])
    )
    print(
        f"  wake-up after the deadline: median {_f(fig.get('wake_late_median_ms'), 3)} ms, p99 "
        f"{_f(fig.get('wake_late_p99_ms'), 3)} ms, max {_f(fig.get('wake_late_max_ms'))} ms; "
        f"late ticks (a deadline passed) {fig.get('late_ticks')}, deadlines dropped "
        f"{fig.get('missed_deadlines')}"
    )
    if fig.get("inject_delays") is not None:
        print(
            f"    of which injected: {_f(fig.get('injected_delay_s'), 3)} s in all, "
            f"{fig.get('injected_stalls')} stalls, {fig.get('injected_freezes')} freeze"
        )
    flying = fig.get("flying_ticks")
    print(
        f"  tick work, the ticks that flew the vehicle (a setpoint sent: "
        f"{'—' if flying is None else flying} ticks): median "
        f"{_f(fig.get('flying_tick_work_median_ms'))} ms, p99 "
        f"{_f(fig.get('flying_tick_work_p99_ms'))} ms (max "
        f"{_f(fig.get('flying_tick_work_max_ms'))})"
        + _verdict(fig.get("flying_tick_work_p99_ms"), TARGETS_MS["tick_work_p99"])
    )
    if fig.get("setpoint_send_p99_ms") is not None:
        print(
            f"    of which the setpoint's send: median {_f(fig['setpoint_send_median_ms'], 3)} "
            f"ms, p99 {_f(fig['setpoint_send_p99_ms'], 3)} ms; in the slowest 1 % of the flying "
            f"ticks {_f(fig.get('slowest_1pc_send_mean_ms'), 3)} of their "
            f"{_f(fig.get('slowest_1pc_work_mean_ms'), 3)} ms on average"
        )
    print(
        f"    all ticks: median {_f(fig.get('tick_work_median_ms'))} ms, p99 "
        f"{_f(fig.get('tick_work_p99_ms'))} ms; the control thread's CPU time: median "
        f"{_f(fig.get('tick_cpu_median_ms'))} ms, p99 {_f(fig.get('tick_cpu_p99_ms'))} ms "
        "(the rest waits for the CPU or a lock)"
    )
    overruns = fig.get("overruns")
    print(
        f"  overruns {overruns}  target 0 in {seconds:g} s: "
        f"{'met' if overruns == 0 else 'NOT MET'}" + _overran(fig.get("overran_ticks"))
    )
    print(
        f"  capture-to-command median {_f(fig.get('capture_to_command_median_ms'), 1)} ms, of "
        f"which beyond the camera's own delay ({1000 * delay_s:.0f} ms): median "
        f"{_f(fig.get('beyond_camera_median_ms'))} ms, p99 {_f(fig.get('beyond_camera_p99_ms'))} ms"
        + _verdict(fig.get("beyond_camera_p99_ms"), TARGETS_MS["beyond_camera_p99"])
    )
    print(
        f"    of which from the detector's result to the command: median "
        f"{_f(fig.get('after_detection_median_ms'))} ms, p99 "
        f"{_f(fig.get('after_detection_p99_ms'))} ms (a fused detection waits for the next tick)"
    )
    cpu = fig.get("cpu_share_of_one_core")
    print(
        f"  onboard process: CPU {_f(None if cpu is None else 100 * cpu, 0)} % of one core, "
        f"peak memory {_f(fig.get('peak_rss_mb'), 0)} MB  target <= 300 MB"
    )
    print(
        f"  TIMESYNC offset error {_f(fig.get('timesync_error_ms'), 3)} ms (quickest round trip "
        f"{_f(fig.get('timesync_min_rtt_ms'), 3)} ms, {fig.get('timesync_samples')} samples)"
    )
    vid = fig.get("video")
    if vid is not None:
        print(
            f"  video (H.264/RTP, decoded here): {vid['frames']} frames ({_f(vid['fps'], 1)}/s), "
            f"glass-to-glass median {_f(vid['latency_median_ms'], 1)} ms, p95 "
            f"{_f(vid['latency_p95_ms'], 1)} ms, of which the camera's own delay "
            f"{1000 * delay_s:.0f} ms; {vid['packets_lost']} packets lost"
        )
    fox = fig.get("foxglove")
    if fox is not None:
        cpu_ms = 1000 * fox["cpu_s"] / seconds if fox.get("cpu_s") else None
        print(
            f"  Foxglove live: {fox['messages_received']} messages received here, "
            f"{fox.get('published_frames')} frames published, {fox.get('dropped')} dropped by "
            f"the control thread's queue; the publishing thread's CPU {_f(cpu_ms, 1)} ms per s"
        )
    result = fig.get("sitl_result")
    if result:
        print(f"  intercept: {result['outcome']}, miss {result['miss_m']:.3f} m")
    host = fig.get("host_wake_latency")
    if host:
        print(
            f"  this host: a 5 ms periodic sleep at normal priority woke p50 "
            f"{_f(host['p50_ms'], 3)} ms, p99 {_f(host['p99_ms'], 3)} ms, max "
            f"{_f(host['max_ms'])} ms late over {host['seconds']:g} s (onboard check-rt)"
        )


def print_summary(summary: dict) -> None:
    """Each target's per-run values, median, worst and in how many runs it was met."""
    print(f"over {next(iter(summary.values()))['of']} runs (a target is met in a run when that "
          "run's figure meets it):")  # fmt: skip
    for key, row in summary.items():
        digits = "g" if key == "overruns" else ".2f"

        def fmt(v, digits=digits) -> str:
            return "—" if v is None else format(v, digits)

        vals = " / ".join(fmt(v) for v in row["runs"])
        print(
            f"  {_NAMES[key]}: {vals}; median {fmt(row['median'])}, worst {fmt(row['worst'])}; "
            f"target <= {row['target_at_most']:g} met in {row['met']} of {row['of']}"
        )
