"""The DKF's cost: ``python -m groundstation.bench.dkf [--repeat N]``.

Two figures, pinned to one core like ``groundstation bench``:

- per call, on a synthetic stream (100 Hz predictions with gyro, velocity and attitude, 30 Hz
  detections fused 80 ms late, 3000 ticks per repeat): ``predict``, ``fuse`` and the
  per-tick reads (``estimate``, ``e_px_at``, ``image_std_px``), median and p99;
- its share of ``groundstation bench``'s projected sorties (static-ahead-20m and
  cv-top-to-bottom, seeds 0-2): every public DKF call and the loop's ``tick`` timed by
  wrappers (each adds ~0.2 us to what it times), in ms per simulated second.

A measuring tool beside the product: it imports only what it measures.
"""

from __future__ import annotations

import argparse
import statistics
import time


def per_call(repeat: int = 3) -> dict[str, tuple[float, float]]:
    """(median, p99) in microseconds of predict, fuse and the per-tick reads."""
    import numpy as np

    from onboard.camera_model import CameraModel
    from onboard.datatypes import Detection
    from onboard.estimation.dkf import DelayedKalmanFilter

    cam = CameraModel()
    rng = np.random.default_rng(0)
    n = 3000
    gyro = rng.normal(size=(n, 3)) * 0.3
    vel = rng.normal(size=(n, 3))
    R_WC = np.array(cam.R_BC)
    out: dict[str, list[int]] = {"predict": [], "fuse": [], "reads": []}
    pc = time.perf_counter_ns
    for _ in range(repeat):
        dkf = DelayedKalmanFilter(cam)
        pending: list[tuple[float, Detection]] = []
        u, v = 330.0, 250.0
        for k in range(n):
            t = 0.01 * k
            t0 = pc()
            dkf.predict(t, gyro[k], vel[k], R_WC)
            out["predict"].append(pc() - t0)
            u, v = u + rng.normal() * 0.3, v + rng.normal() * 0.3
            if k % 3 == 0:
                pending.append((t + 0.08, Detection(t, (u, v), (u - 3, v - 3, 6, 6), 28.0)))
            for item in [p for p in pending if p[0] <= t + 1e-9]:
                pending.remove(item)
                t0 = pc()
                dkf.fuse(item[1])
                out["fuse"].append(pc() - t0)
            t0 = pc()
            dkf.estimate()
            dkf.e_px_at(t - 0.01)
            dkf.image_std_px()
            out["reads"].append(pc() - t0)
    return {
        k: (statistics.median(v) / 1e3, float(np.percentile(v, 99)) / 1e3) for k, v in out.items()
    }


def share() -> dict[str, float]:
    """ms per simulated second of the DKF's public calls and of the loop's tick, and the
    sortie's wall time, over the bench's six projected sorties."""
    from onboard.estimation.dkf import DelayedKalmanFilter
    from onboard.loop import InterceptionLoop

    from ..scenario import load_scenario
    from ..sim.simulation import Simulation
    from .core import BENCH_SCENARIOS

    spent: dict[str, int] = {}
    pc = time.perf_counter_ns

    def timed(cls, name: str, key: str) -> None:
        fn = getattr(cls, name)

        def wrapper(*args, **kwargs):
            t0 = pc()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[key] = spent.get(key, 0) + pc() - t0

        setattr(cls, name, wrapper)
        originals.append((cls, name, fn))

    originals: list = []
    names = ("predict", "fuse", "estimate", "e_px_at", "range_m", "depth_velocity")
    names += ("image_std_px", "state_vector", "lost")
    try:
        for name in names:
            timed(DelayedKalmanFilter, name, "dkf")
        timed(InterceptionLoop, "tick", "tick")
        sims = [
            Simulation(load_scenario(s), "png", seed, keep_records=False)
            for s in BENCH_SCENARIOS
            for seed in range(3)
        ]
        t0 = pc()
        sim_s = sum(sim.run().sim_time_s for sim in sims)
        wall = pc() - t0
    finally:
        for cls, name, fn in originals:
            setattr(cls, name, fn)
    per_s = 1e6 * sim_s
    return {
        "dkf_ms_per_sim_s": spent.get("dkf", 0) / per_s,
        "tick_ms_per_sim_s": spent.get("tick", 0) / per_s,
        "sortie_ms_per_sim_s": wall / per_s,
    }


def main(argv: list[str] | None = None) -> int:
    from .core import _pin_one_core

    parser = argparse.ArgumentParser(prog="python -m groundstation.bench.dkf")
    parser.add_argument("--repeat", type=int, default=3, help="streams of 3000 ticks")
    args = parser.parse_args(argv)
    print(f"DKF cost ({_pin_one_core()})")
    labels = {"predict": "predict", "fuse": "fuse", "reads": "estimate+e_px_at+image_std_px"}
    for name, (med, p99) in per_call(max(args.repeat, 1)).items():
        print(f"  {labels[name]:30s} median {med:6.1f} us  p99 {p99:6.1f} us")
    s = share()
    dkf, tick, wall = s["dkf_ms_per_sim_s"], s["tick_ms_per_sim_s"], s["sortie_ms_per_sim_s"]
    print(
        f"  bench sorties, per simulated s: DKF {dkf:.2f} ms of the loop's tick {tick:.2f} ms"
        f" ({100 * dkf / tick:.0f} %) and of the sortie {wall:.2f} ms ({100 * dkf / wall:.0f} %)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
