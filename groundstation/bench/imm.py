"""The IMM's cost: ``python -m groundstation.bench.imm [--repeat N]``.

One figure: the time of :meth:`onboard.estimation.imm.TargetMotionImm.update` (predict and
fuse, three models), median and p99 in microseconds, over a seeded synthetic stream: a target
20 m ahead at 4 m/s that turns at 3 m/s^2 after 4 s, its position measured at 30 Hz with
noise, 900 updates a repeat.

A measuring tool beside the product: it imports only what it measures.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time


def per_update(repeat: int = 3) -> tuple[float, float]:
    """(median, p99) in microseconds of one IMM update."""
    import numpy as np

    from onboard.estimation.imm import TargetMotionImm

    dt = 1.0 / 30.0
    R = np.diag([0.05**2, 0.4**2, 0.05**2])
    times: list[float] = []
    for r in range(repeat):
        rng = np.random.default_rng(r)
        imm = TargetMotionImm()
        p, v = np.array([0.0, 20.0, 10.0]), np.array([4.0, 0.0, 0.0])
        camera = np.zeros(3)
        for k in range(900):
            if k * dt > 4.0:
                w = 3.0 / 4.0 * dt
                c, s = math.cos(w), math.sin(w)
                v = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], 0.0])
            p = p + v * dt
            z = p + rng.multivariate_normal(np.zeros(3), R)
            t0 = time.perf_counter()
            imm.update(k * dt, z, R, v, camera)
            times.append(time.perf_counter() - t0)
    times.sort()
    return statistics.median(times) * 1e6, times[int(0.99 * (len(times) - 1))] * 1e6


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="streams of 900 updates")
    args = ap.parse_args(argv)
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")
    median, p99 = per_update(args.repeat)
    print(f"IMM update: median {median:.0f} us, p99 {p99:.0f} us ({args.repeat * 900} updates)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
