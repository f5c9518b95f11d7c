"""The DKF's cost: ``python -m groundstation.bench.dkf [--repeat N]``.

Two figures, pinned to one core like ``groundstation bench``:

- per call, on a synthetic stream (100 Hz predictions with gyro, velocity and attitude, 30 Hz
  detections fused 80 ms late, 3000 ticks per repeat): ``predict``, ``fuse`` and the
  per-tick reads (``estimate``, ``e_px_at``, ``image_std_px``), median and p99;
- its share of ``groundstation bench``'s projected sorties (static-ahead-20m and
  cv-top-to-bottom, seeds 0-2): every public DKF call and the loop's ``tick`` timed by
  wrappers (each adds ~0.2 us to what it times), in ms per simulated second.

``--trace N`` instead prints every output of the filter driven through N seeded awkward
streams (late, out-of-order, duplicate and outlying detections, gaps that lose the track,
re-starts that carry it, non-finite inputs, inputs as lists): run it from two trees and
``diff`` the outputs to check a change to the filter flies the same numbers.

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


def trace(n_streams: int) -> list[str]:
    """Every output of the DKF over n_streams seeded streams, as ``repr`` lines."""
    import math

    import numpy as np

    from onboard.camera_model import CameraModel
    from onboard.datatypes import Detection
    from onboard.estimation.dkf import DelayedKalmanFilter, DkfConfig
    from onboard.geometry import attitude_from_yaw_pitch_roll

    cam = CameraModel()
    out: list[str] = []

    def rec(*a) -> None:
        out.append(repr(a))

    for seed in range(n_streams):
        rng = np.random.default_rng(seed)
        dkf = DelayedKalmanFilter(cam, DkfConfig(buffer_s=float(rng.choice([0.3, 0.6, 1.5]))))
        dkf.carry_max_s = float(rng.choice([0.0, 1.0, 5.0]))
        t, gap_until, rng_m = 0.0, -1.0, 20.0
        pending: list[tuple[float, Detection]] = []
        u, v = 320.0 + rng.normal() * 50, 240.0 + rng.normal() * 50
        yaw, pitch = float(rng.normal()), float(rng.normal()) * 0.2
        R = attitude_from_yaw_pitch_roll(yaw, pitch, 0.0) @ cam.R_BC
        for _ in range(int(rng.integers(300, 900))):
            t += float(rng.choice([0.005, 0.01, 0.0101, 0.02]))
            w, vel = rng.normal(size=3) * 0.5, rng.normal(size=3) * 3
            if rng.random() < 0.01:
                w[int(rng.integers(3))] = math.nan
            R_k = R if rng.random() > 0.01 else np.full((3, 3), math.nan)
            mode = rng.random()
            if mode < 0.1:
                dkf.predict(t, w)
            elif mode < 0.2:
                dkf.predict(t, list(w), tuple(vel), R_k.tolist())
            else:
                dkf.predict(t, w, vel, R_k)
            u = min(max(u + rng.normal() * 3, 5.0), 635.0)
            v = min(max(v + rng.normal() * 3, 5.0), 475.0)
            rng_m = max(rng_m - 0.03, 2.0)
            if rng.random() < 0.005:
                gap_until = t + float(rng.uniform(0.3, 1.5))
            if rng.random() < 0.3 and t > gap_until:
                r = cam.f_px * 0.15 / rng_m
                cu, cv = u + rng.normal(), v + rng.normal()
                if rng.random() < 0.05:
                    cu, cv = cu + 200, cv - 150  # an outlier
                area = math.pi * r * r if rng.random() > 0.1 else math.nan
                det = Detection(t, (cu, cv), (cu - r, cv - r, 2 * r, 2 * r), area)
                delay = float(rng.choice([0.0, 0.03, 0.08, 0.15, 0.7]))
                pending.append((t + delay + float(rng.uniform(0, 0.02)), det))
            if rng.random() < 0.02 and pending:
                pending.append((t, pending[0][1]))  # a duplicate
            due = [p for p in pending if p[0] <= t]
            rng.shuffle(due)  # out of order
            for p in due:
                pending.remove(p)
                rec("fuse", dkf.fuse(p[1]).value)
            est = dkf.estimate()
            if est is not None:
                est = (est.time_s, est.e_px, est.e_rate_px_s, est.time_since_detection_s, est.lost)
            rec("estimate", est)
            q = rng.random()
            if q < 0.3:
                sv = dkf.state_vector()
                rec("state_vector", None if sv is None else (sv[0].tolist(), sv[1].tolist()))
            elif q < 0.4:
                dv = dkf.depth_velocity()
                rec(
                    "depth_velocity",
                    None if dv is None else (dv[0], dv[1].tolist(), dv[2].tolist()),
                )
            elif q < 0.5:
                rec("reads", dkf.image_std_px(), dkf.range_m(), dkf.lost(), dkf.time_s)
            rec("e_px_at", dkf.e_px_at(t - float(rng.choice([0.0, 0.01, 0.05, 0.2]))))
        rec("counts", {k.value: c for k, c in dkf.counts.items()})
    return out


def main(argv: list[str] | None = None) -> int:
    from .core import _pin_one_core

    parser = argparse.ArgumentParser(prog="python -m groundstation.bench.dkf")
    parser.add_argument("--repeat", type=int, default=3, help="streams of 3000 ticks")
    parser.add_argument("--trace", type=int, default=0, help="print N streams' outputs instead")
    args = parser.parse_args(argv)
    if args.trace > 0:
        print("\n".join(trace(args.trace)))
        return 0
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
