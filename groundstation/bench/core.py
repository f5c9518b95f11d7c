"""``groundstation bench``: speed and memory figures of the interception core.

Prints the simulator's real-time factor per camera mode, the control tick's median and p99
time, the detector's and the renderer's time per 640x480 frame, and peak memory. Pinned to one
core (and OpenCV to one thread) unless told otherwise. Figures are medians over repeated
sorties measured in this one run; the machine is shared, so compare ratios, not single runs.
"""

from __future__ import annotations

import dataclasses
import json
import os
import resource
import statistics
import time

import cv2
import numpy as np

from onboard.perception import RedBalloonDetector

from ..scenario import load_scenario
from ..sim.simulation import Simulation

BENCH_SCENARIOS = ("static-ahead-20m", "cv-top-to-bottom")
TARGETS = {  # projected >= 200x per core, rendered >= 20x, tick median <= 0.1 ms
    "rtf_projected": 200.0,
    "rtf_rendered": 20.0,
    "rtf_projected_cpu": 200.0,
    "rtf_rendered_cpu": 20.0,
    "tick_median_ms": 0.1,
    "detector_median_ms": 3.0,
}


def _pin_one_core() -> str:
    cv2.setNumThreads(1)
    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return f"pinned to CPU {cpu}, OpenCV 1 thread"
    return "OpenCV 1 thread (no CPU pinning on this OS)"


def _real_time_factors(mode: str, repeat: int) -> tuple[list[float], list[float]]:
    """Simulated over wall seconds, and over this process's CPU seconds (the figure per core
    that other programs on a shared machine disturb least)."""
    rtfs, rtfs_cpu = [], []
    for name in BENCH_SCENARIOS:
        scenario = load_scenario(name)
        for seed in range(repeat):
            sim = Simulation(scenario, "png", seed, mode, keep_records=False)
            t0, c0 = time.perf_counter(), time.process_time()
            result = sim.run()
            rtfs.append(result.sim_time_s / (time.perf_counter() - t0))
            rtfs_cpu.append(result.sim_time_s / max(time.process_time() - c0, 1e-9))
    return rtfs, rtfs_cpu


def _tick_times_ms(repeat: int, sleep_s: float = 0.0) -> tuple[list[float], list[float]]:
    """Control tick times (ms) without and with a detection fused in the tick (the DKF's
    replay of its buffer runs only in the latter). ``sleep_s``: the thread sleeps that long
    before each tick (not timed), as the vehicle's control thread sleeps between ticks."""
    plain, fusing = [], []
    for seed in range(repeat):
        sim = Simulation(load_scenario("cv-top-to-bottom"), "png", seed, keep_records=False)
        loop = sim.loop
        tick = loop.tick

        def timed(state, _tick=tick, _loop=loop):
            if sleep_s > 0.0:
                time.sleep(sleep_s)
            t0 = time.perf_counter()
            out = _tick(state)
            ms = (time.perf_counter() - t0) * 1e3
            (fusing if _loop.last_fusion else plain).append(ms)
            return out

        loop.tick = timed  # type: ignore[method-assign]
        sim.run()
    return plain, fusing


def _frame_times_ms() -> tuple[list[float], list[float], int, list[float], float]:
    """Renderer and detector time per frame, measured inside a rendered sortie; the detector
    as flown (a window while it tracks) and searching every frame whole, on the same frames."""
    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, "rendered", keep_records=False)
    renderer, detector = sim.camera.renderer, sim.camera.detector
    render_ms, detect_ms, found, full_ms = [], [], [0], []
    render, detect = renderer.render, detector.detect
    full = RedBalloonDetector(dataclasses.replace(detector.config, roi=False)).detect

    def timed_render(*a, **k):
        t0 = time.perf_counter()
        f = render(*a, **k)
        render_ms.append((time.perf_counter() - t0) * 1e3)
        return f

    def timed_detect(frame, t):
        t0 = time.perf_counter()
        det = detect(frame, t)
        detect_ms.append((time.perf_counter() - t0) * 1e3)
        found[0] += det is not None
        t0 = time.perf_counter()
        full(frame, t)
        full_ms.append((time.perf_counter() - t0) * 1e3)
        return det

    renderer.render = timed_render  # type: ignore[method-assign]
    detector.detect = timed_detect  # type: ignore[method-assign]
    sim.run()
    st = detector.stats
    return detect_ms, render_ms, found[0], full_ms, st.windowed / max(st.windowed + st.full, 1)


def _p99(xs: list[float]) -> float:
    return float(np.percentile(xs, 99))


def run_bench(repeat: int = 5, pin_one_core: bool = True, as_json: bool = False) -> int:
    where = _pin_one_core() if pin_one_core else "all cores"
    _real_time_factors("projected", 1)  # warm up imports and caches
    load_before = os.getloadavg()[0]
    rtf_p, rtf_p_cpu = _real_time_factors("projected", repeat)
    rtf_r, rtf_r_cpu = _real_time_factors("rendered", max(1, repeat // 2))
    ticks_plain, ticks_fusing = _tick_times_ms(repeat)
    ticks = ticks_plain + ticks_fusing
    detect_ms, render_ms, found, full_ms, windowed = _frame_times_ms()
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    figures = {
        "where": where,
        "rtf_projected": statistics.median(rtf_p),
        "rtf_projected_min": min(rtf_p),
        "rtf_rendered": statistics.median(rtf_r),
        "rtf_rendered_min": min(rtf_r),
        "rtf_projected_cpu": statistics.median(rtf_p_cpu),
        "rtf_rendered_cpu": statistics.median(rtf_r_cpu),
        "load_average_1min_before_after": [load_before, os.getloadavg()[0]],
        "tick_median_ms": statistics.median(ticks),
        "tick_p99_ms": _p99(ticks),
        "ticks": len(ticks),
        "tick_median_without_fusion_ms": statistics.median(ticks_plain),
        "tick_median_with_fusion_ms": statistics.median(ticks_fusing),
        "ticks_with_fusion": len(ticks_fusing),
        "detector_median_ms": statistics.median(detect_ms),
        "detector_p99_ms": _p99(detect_ms),
        "detector_full_frame_median_ms": statistics.median(full_ms),
        "detector_full_frame_p99_ms": _p99(full_ms),
        "detector_windowed_fraction": windowed,
        "render_median_ms": statistics.median(render_ms),
        "frames": len(detect_ms),
        "frames_with_detection": found,
        "peak_rss_mb": peak_mb,
    }
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0
    la = figures["load_average_1min_before_after"]
    print(
        f"Peregrine core benchmark ({where}); scenarios {', '.join(BENCH_SCENARIOS)}; "
        f"load average {la[0]:.1f} -> {la[1]:.1f} on {os.cpu_count()} CPUs"
    )
    rows = [
        (
            "real-time factor, projected",
            "rtf_projected",
            "x",
            f"min {figures['rtf_projected_min']:.1f}x",
        ),
        (
            "real-time factor, rendered",
            "rtf_rendered",
            "x",
            f"min {figures['rtf_rendered_min']:.1f}x",
        ),
        (
            "real-time factor per CPU s, proj.",
            "rtf_projected_cpu",
            "x",
            "simulated s per CPU s",
        ),
        (
            "real-time factor per CPU s, rend.",
            "rtf_rendered_cpu",
            "x",
            "",
        ),
        (
            "control tick, median",
            "tick_median_ms",
            " ms",
            f"p99 {figures['tick_p99_ms']:.3f} ms over {len(ticks)} ticks",
        ),
        (
            "  tick without / with a fusion",
            "tick_median_without_fusion_ms",
            " ms",
            f"/ {figures['tick_median_with_fusion_ms']:.3f} ms (DKF replay) in "
            f"{figures['ticks_with_fusion']} ticks",
        ),
        (
            "detector per 640x480 frame",
            "detector_median_ms",
            " ms",
            f"p99 {figures['detector_p99_ms']:.2f} ms, {len(detect_ms)} frames, "
            f"{100 * windowed:.0f} % in a window",
        ),
        (
            "  detector searching frames whole",
            "detector_full_frame_median_ms",
            " ms",
            f"p99 {figures['detector_full_frame_p99_ms']:.2f} ms, the same frames",
        ),
        ("renderer per frame", "render_median_ms", " ms", ""),
        ("peak memory (RSS)", "peak_rss_mb", " MB", "whole benchmark process"),
    ]
    for label, key, unit, extra in rows:
        value = figures[key]
        target = TARGETS.get(key)
        verdict = ""
        if target is not None:
            higher_is_better = key.startswith("rtf")
            ok = value >= target if higher_is_better else value <= target
            sign = ">=" if higher_is_better else "<="
            verdict = f"  target {sign} {target:g}{unit.strip()}: {'met' if ok else 'NOT MET'}"
        print(f"  {label:30s} {value:9.3f}{unit:3s} {extra}{verdict}")
    return 0


# ---------------------------------------------------------------------- onboard vs SITL
