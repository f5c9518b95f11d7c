"""``groundstation bench --serve-start``: how long ``groundstation serve`` takes to print its
URL, started as a user starts it (a new process of this interpreter, the numba cache and the
bytecode as installed), in wall seconds and in CPU seconds of the server process up to that
line (the CPU figure barely depends on what else the machine runs; the wall one does)."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from .sitl import _proc_cpu_s  # user plus system CPU seconds of a process (Linux)


def _one_start(timeout_s: float = 120.0) -> tuple[float, float | None]:
    with tempfile.TemporaryDirectory(prefix="peregrine-serve-") as d:
        cmd = [sys.executable, "-m", "groundstation", "serve", "--port", "0"]
        cmd += ["--log-dir", f"{d}/logs", "--data-dir", d]
        # as a user starts it: `bench` runs with the kernels compiled (PEREGRINE_JIT=1 in
        # its environment), `serve` does not
        env = {k: v for k, v in os.environ.items() if k != "PEREGRINE_JIT"}
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=d, env=env
        )
        try:
            for line in proc.stdout:
                if "open http" in line:
                    return time.perf_counter() - t0, _proc_cpu_s(proc.pid)
                if time.perf_counter() - t0 > timeout_s:
                    break
            raise RuntimeError("groundstation serve printed no URL")
        finally:
            proc.terminate()
            proc.wait(10)


def run_serve_start_bench(runs: int = 3, as_json: bool = False) -> int:
    starts = [_one_start() for _ in range(runs)]
    wall = [w for w, _ in starts]
    cpu = [c for _, c in starts if c is not None]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    out = {
        "runs": runs,
        "wall_s": wall,
        "cpu_s": cpu,
        "wall_median_s": statistics.median(wall),
        "cpu_median_s": statistics.median(cpu) if cpu else None,
        "load_average": load,
    }
    if as_json:
        print(json.dumps(out))
        return 0
    print(f"groundstation serve until it prints its URL ({runs} starts, load average {load:.1f}):")
    print(f"  wall: median {out['wall_median_s']:.2f} s ({', '.join(f'{w:.2f}' for w in wall)})")
    if cpu:
        print(f"  CPU of the server process: median {out['cpu_median_s']:.2f} s")
    return 0
