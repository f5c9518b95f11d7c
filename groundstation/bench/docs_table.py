"""The manual's benchmark page, docs/benchmarks.md, written from a fresh run of the benchmarks.

``python -m groundstation.bench.docs_table [--repeat 2] [--kinds core,campaigns,recording,
dashboard] [--out docs/benchmarks.md]`` runs each ``groundstation bench`` kind once (with
``--json``, in a subprocess of its own) and writes one table: each figure with the command
that measures it, then the machine, the date and the load average while it ran. Run by hand,
not in CI: the figures depend on the machine and on what else it is doing.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

KINDS = ("core", "campaigns", "recording", "dashboard")
FLAGS = {"core": [], "campaigns": ["--campaigns"], "recording": ["--recording"]}
FLAGS["dashboard"] = ["--dashboard"]

Row = tuple[str, Callable[[dict], str]]

ROWS: dict[str, list[Row]] = {
    "core": [
        (
            "simulator real-time factor, projected camera, one core (median)",
            lambda f: f"{f['rtf_projected']:.0f}x (slowest {f['rtf_projected_min']:.0f}x)",
        ),
        (
            "simulator real-time factor, rendered camera, one core (median)",
            lambda f: f"{f['rtf_rendered']:.1f}x (slowest {f['rtf_rendered_min']:.1f}x)",
        ),
        (
            "control tick (the loop's work per tick), median / p99",
            lambda f: f"{f['tick_median_ms']:.3f} / {f['tick_p99_ms']:.3f} ms",
        ),
        (
            "control tick with a detection fused, median",
            lambda f: f"{f['tick_median_with_fusion_ms']:.3f} ms",
        ),
        (
            "red-balloon detector per 640x480 frame, median / p99",
            lambda f: f"{f['detector_median_ms']:.2f} / {f['detector_p99_ms']:.2f} ms",
        ),
        ("renderer per 640x480 frame, median", lambda f: f"{f['render_median_ms']:.2f} ms"),
        ("peak memory of the benchmark process", lambda f: f"{f['peak_rss_mb']:.0f} MB"),
    ],
    "campaigns": [
        (
            "campaign throughput, static n=20 (60 sorties), 1 worker",
            lambda f: f"{f['throughput_1_workers']:.1f} sortie-s per wall s",
        ),
        (
            "campaign throughput, the same, 2 workers",
            lambda f: (
                f"{f['throughput_2_workers']:.1f} sortie-s per wall s ({f['speedup_2_vs_1']:.2f}x)"
            ),
        ),
        (
            "full static campaign (150 sorties), wall time",
            lambda f: (
                f"{f['static50_wall_s']:.1f} s on {f['static50_workers']} workers "
                f"({f['per_1000_sorties_wall_s']:.0f} s per 1000 sorties)"
            ),
        ),
    ],
    "recording": [
        (
            "recording's cost to a sortie, projected / rendered camera",
            lambda f: (
                f"{100 * f['recording_overhead_projected']:.1f} / "
                f"{100 * f['recording_overhead_rendered']:.1f} %"
            ),
        ),
        (
            "Sorties list of 200 logs, first time / after",
            lambda f: f"{f['list_200_cold_s']:.2f} s / {1000 * f['list_200_warm_s']:.0f} ms",
        ),
        (
            "seek to 5:00 in a 10-minute rendered sortie",
            lambda f: (
                f"{1000 * f['seek_s']:.0f} ms, {100 * f['seek_read_fraction']:.1f} % "
                f"of the {f['long_file_mb']:.0f} MB file read"
            ),
        ),
    ],
    "dashboard": [
        (
            "dashboard at 1x, 5 viewers: simulator's share of real time",
            lambda f: f"{100 * f['sim_real_time_share']:.0f} %",
        ),
        (
            "the same: telemetry painted per viewer",
            lambda f: _span(f["painted_hz"], "frames/s"),
        ),
        (
            "the 5 viewers open with no sortie: browser CPU",
            lambda f: f"{f['idle_cpu_percent_of_a_core']['browser']:.0f} % of one core",
        ),
    ],
}


def _span(values: list[float | None], unit: str) -> str:
    """The range of a per-viewer figure (a viewer that reported nothing left out)."""
    known = [v for v in values if v is not None]
    return f"{min(known):.0f}-{max(known):.0f} {unit}" if known else "none reported"


def _command(kind: str, repeat: int) -> list[str]:
    extra = ["--repeat", str(repeat)] if kind == "core" else []
    return ["groundstation", "bench", *FLAGS[kind], *extra]


def _run(argv: list[str]) -> dict:
    cmd = [sys.executable, "-m", "groundstation", *argv[1:], "--json"]
    out = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"docs_table: `{' '.join(argv)}` failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout[out.stdout.index("{") :])


def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        kb = int(Path("/proc/meminfo").read_text().split()[1])
        mem = f", {kb / 2**20:.0f} GB RAM"
    except (OSError, ValueError, IndexError):
        pass
    return (
        f"{cpu}, {os.cpu_count()} CPUs{mem}; {platform.system()} {platform.release()}; "
        f"Python {platform.python_version()}"
    )


def _kernels() -> str:
    """The mode the benchmark commands ran the kernels in (they call use_jit, as here)."""
    code = "import onboard.jit as j; print('compiled' if j.use_jit() else 'plain Python')"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    return out.stdout.strip() or "unknown"


def page(results: dict[str, dict], repeat: int, machine: str, kernels: str, date: str) -> str:
    """The Markdown of docs/benchmarks.md from the benchmarks' JSON figures."""
    lines = [
        "# Benchmarks",
        "",
        "Current figures, each with the command that measures it. This page is written by",
        "`python -m groundstation.bench.docs_table` (run by hand, not in CI), which runs every",
        "command below once and replaces the page.",
        "",
        "| figure | measured | command |",
        "|---|---|---|",
    ]
    for kind, rows in ROWS.items():
        if kind not in results:
            continue
        cmd = " ".join(_command(kind, repeat))
        for name, fmt in rows:
            lines.append(f"| {name} | {fmt(results[kind])} | `{cmd}` |")
    loads = []
    for kind, f in results.items():
        la = f.get("load_average_1min_before_after") or f.get("load_average_before_after")
        if la is None and "load_average_1min" in f:
            la = [f["load_average_1min"]]
        if la:
            loads.append(f"{kind} {' -> '.join(f'{x:.1f}' for x in la)}")
    lines += [
        "",
        f"Measured on {date} (UTC) on {machine}; the kernels ran {kernels}.",
        f"Load average (1 min) during each run: {'; '.join(loads)}. The machine was shared with",
        "other work, so figures scatter from run to run; compare ratios measured in one run.",
        f"`groundstation bench` flew {repeat} sorties per camera mode here (`--repeat {repeat}`;",
        "its default is 5): a small count, so its medians are rough. The campaign, recording",
        "and dashboard benchmarks have fixed sizes (the rows say them).",
        "",
        "What the commands measure:",
        "",
        "- `groundstation bench`: the simulator's real-time factor per camera mode (simulated",
        "  seconds per wall second, pinned to one core), the control tick's time, the detector's",
        "  and the renderer's time per frame, and peak memory.",
        "- `groundstation bench --campaigns`: campaign throughput with 1 and 2 workers and the",
        "  full static campaign's wall time.",
        "- `groundstation bench --recording`: what recording to MCAP adds to a sortie, listing",
        "  200 logs, and seeking in a long recording.",
        "- `groundstation bench --dashboard`: the dashboard at 1x with five visible viewers",
        "  (headless Chromium, software WebGL).",
        "- `groundstation bench --overlay`: the overlay page with 20 recorded sorties: how long",
        "  it takes to open (and how much of it is the request), cold and warm, and scrub",
        "  frames/s (docs/operator-gains.md; not part of this table).",
        "- `groundstation bench --serve-start --runs 3`: seconds until `groundstation serve`",
        "  prints its URL, wall and CPU of the server process, medians (the start-up figures in",
        "  docs/kernels.md; not part of this table).",
        "- `groundstation bench --sitl`: `onboard run` against the SITL vehicle (loop rate,",
        "  jitter, latency, CPU, memory); it runs in real time and needs a quiet machine, so it",
        "  is not part of this table.",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m groundstation.bench.docs_table")
    ap.add_argument("--repeat", type=int, default=2, help="sorties per camera mode (core)")
    ap.add_argument(
        "--kinds", default=",".join(KINDS), help="comma-separated, of " + ",".join(KINDS)
    )
    ap.add_argument("--out", type=Path, default=Path("docs/benchmarks.md"))
    args = ap.parse_args(argv)
    kinds = [k for k in args.kinds.split(",") if k]
    unknown = sorted(set(kinds) - set(KINDS))
    if unknown or args.repeat < 1:
        ap.error(f"--kinds: unknown {unknown}" if unknown else "--repeat must be >= 1")
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    results = {}
    for kind in kinds:
        cmd = _command(kind, args.repeat)
        print(f"docs_table: {' '.join(cmd)}", file=sys.stderr)
        results[kind] = _run(cmd)
    args.out.write_text(page(results, args.repeat, _machine(), _kernels(), date))
    print(f"docs_table: wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
