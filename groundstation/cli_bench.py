"""``groundstation bench``'s options and dispatch (the measurements are in
:mod:`groundstation.bench`, imported only when one runs)."""

from __future__ import annotations

import argparse

from .cli_options import COUNT, seconds


def _priority(text: str) -> str:
    """``--realtime``: a SCHED_FIFO priority of 1 to 99, or ``off``."""
    if text == "off" or (text.isdigit() and 1 <= int(text) <= 99):
        return text
    raise argparse.ArgumentTypeError(f"must be a priority of 1 to 99 or off, got {text!r}")


def add_bench_parser(sub) -> None:
    b = sub.add_parser("bench", help="print speed and memory figures (docs/benchmarks.md)")
    b.add_argument("--repeat", type=COUNT, default=5, help="sorties per camera mode")
    b.add_argument("--all-cores", action="store_true", help="do not pin to one core")
    b.add_argument("--json", action="store_true")
    b.add_argument("--campaigns", action="store_true", help="campaign throughput instead")
    b.add_argument(
        "--recording",
        action="store_true",
        help="recording cost, listing 200 logs, seeking in a 10-minute sortie",
    )
    b.add_argument(
        "--sitl",
        action="store_true",
        help="onboard run against the SITL vehicle: loop rate, jitter, latency, CPU, memory, "
        "the intercept (docs/realtime.md)",
    )
    b.add_argument(
        "--seconds", type=seconds(0, False), default=20.0, help="--sitl: how long to fly"
    )
    b.add_argument(
        "--runs",
        type=COUNT,
        default=1,
        help="--sitl: fly this many times; each run's figures, then each target's per-run "
        "values and in how many runs it was met. --serve-start: start the server this many "
        "times",
    )
    b.add_argument(
        "--realtime",
        type=_priority,
        metavar="PRIO|off",
        help="--sitl: onboard run --realtime PRIO|off (default: the runtime's); with a priority "
        "the SITL runs under SCHED_FIFO too",
    )
    b.add_argument(
        "--inject-delays",
        type=int,
        metavar="SEED",
        help="--sitl: onboard run --inject-delays SEED (fault injection: the control thread's "
        "wake-ups delayed, p99 5 ms, a 30 ms stall each second, one 150 ms freeze)",
    )
    b.add_argument(
        "--sitl-placement",
        choices=("apart", "shared"),
        default="apart",
        help="--sitl: apart (default) runs the SITL under SCHED_BATCH, so it does not preempt "
        "the onboard run's threads when it wakes, as a flight controller of its own, and polls "
        "the ground link under SCHED_IDLE, as a ground station on a computer of its own; "
        "shared leaves both where the system puts them",
    )
    b.add_argument(
        "--video",
        action="store_true",
        help="--sitl: the onboard process also streams its camera (H.264/RTP) to a receiver "
        "here: glass-to-glass latency",
    )
    b.add_argument(
        "--foxglove",
        dest="foxglove_client",
        action="store_true",
        help="--sitl: the onboard process also publishes to Foxglove (onboard run --foxglove), "
        "a client here subscribed to every channel: what it costs the control tick",
    )
    b.add_argument(
        "--dashboard",
        action="store_true",
        help="dashboard with 5 browser tabs instead (needs chromium)",
    )
    b.add_argument(
        "--overlay",
        action="store_true",
        help="the Sorties overlay page with 20 recorded sorties: open time, scrub frames/s "
        "(needs chromium)",
    )
    b.add_argument(
        "--serve-start",
        action="store_true",
        help="`groundstation serve` started --runs times: seconds until it prints its URL, "
        "wall and CPU (their medians)",
    )


def run_bench_command(args: argparse.Namespace) -> int:
    from .bench import (
        run_bench,
        run_campaign_bench,
        run_dashboard_bench,
        run_overlay_bench,
        run_recording_bench,
        run_serve_start_bench,
        run_sitl_bench,
    )

    if args.sitl:
        return run_sitl_bench(
            args.seconds,
            as_json=args.json,
            realtime=args.realtime,
            video=args.video,
            foxglove=args.foxglove_client,
            runs=args.runs,
            sitl_placement=args.sitl_placement,
            inject_delays=args.inject_delays,
        )
    if args.recording:
        return run_recording_bench(as_json=args.json)
    if args.dashboard:
        return run_dashboard_bench(as_json=args.json)
    if args.overlay:
        return run_overlay_bench(as_json=args.json)
    if args.serve_start:
        return run_serve_start_bench(runs=args.runs, as_json=args.json)
    if args.campaigns:
        return run_campaign_bench(as_json=args.json)
    return run_bench(args.repeat, pin_one_core=not args.all_cores, as_json=args.json)
