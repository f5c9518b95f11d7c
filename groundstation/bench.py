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
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from .scenario import load_scenario
from .sim.simulation import Simulation

BENCH_SCENARIOS = ("static-ahead-20m", "cv-top-to-bottom")
TARGETS = {
    "rtf_projected": 50.0,
    "rtf_rendered": 10.0,
    "tick_median_ms": 0.3,
    "detector_median_ms": 3.0,
}


def _pin_one_core() -> str:
    cv2.setNumThreads(1)
    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return f"pinned to CPU {cpu}, OpenCV 1 thread"
    return "OpenCV 1 thread (no CPU pinning on this OS)"


def _real_time_factors(mode: str, repeat: int) -> list[float]:
    rtfs = []
    for name in BENCH_SCENARIOS:
        scenario = load_scenario(name)
        for seed in range(repeat):
            sim = Simulation(scenario, "png", seed, mode, keep_records=False)
            t0 = time.perf_counter()
            result = sim.run()
            rtfs.append(result.sim_time_s / (time.perf_counter() - t0))
    return rtfs


def _tick_times_ms(repeat: int) -> list[float]:
    times = []
    for seed in range(repeat):
        sim = Simulation(load_scenario("cv-top-to-bottom"), "png", seed, keep_records=False)
        tick = sim.loop.tick

        def timed(state, _tick=tick):
            t0 = time.perf_counter()
            out = _tick(state)
            times.append((time.perf_counter() - t0) * 1e3)
            return out

        sim.loop.tick = timed  # type: ignore[method-assign]
        sim.run()
    return times


def _frame_times_ms() -> tuple[list[float], list[float], int]:
    """Renderer and detector time per frame, measured inside a rendered sortie."""
    sim = Simulation(load_scenario("cv-top-to-bottom"), "png", 0, "rendered", keep_records=False)
    renderer, detector = sim.camera.renderer, sim.camera.detector
    render_ms, detect_ms, found = [], [], [0]
    render, detect = renderer.render, detector.detect

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
        return det

    renderer.render = timed_render  # type: ignore[method-assign]
    detector.detect = timed_detect  # type: ignore[method-assign]
    sim.run()
    return detect_ms, render_ms, found[0]


def run_campaign_bench(as_json: bool = False) -> int:
    """Campaign throughput (simulated sortie-seconds per wall second) with 1 and 2 workers,
    and the wall time of the full static campaign (50 targets x 3 laws, projected)."""
    import tempfile
    from pathlib import Path

    from .campaigns.driver import run_campaign
    from .campaigns.runner import default_workers

    figures: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for workers in (1, 2):
            res = run_campaign(
                "static", n=20, workers=workers, progress=False, out=Path(tmp) / f"w{workers}"
            )
            figures[f"throughput_{workers}_workers"] = res["meta"]["throughput_sim_s_per_s"]
            figures[f"wall_s_{workers}_workers"] = res["meta"]["wall_s"]
        res = run_campaign(
            "static", workers=default_workers(), progress=False, out=Path(tmp) / "full"
        )
        figures["static50_wall_s"] = res["meta"]["wall_s"]
        figures["static50_sorties"] = res["meta"]["sorties"]
        figures["static50_workers"] = res["meta"]["workers"]
    figures["speedup_2_vs_1"] = figures["throughput_2_workers"] / figures["throughput_1_workers"]
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0
    print("Campaign benchmark: static, projected, laws png,pg,ibvs")
    for w in (1, 2):
        print(
            f"  n=20 (60 sorties), {w} worker(s): {figures[f'throughput_{w}_workers']:6.1f} "
            f"sortie-s per wall s ({figures[f'wall_s_{w}_workers']:.1f} s wall)"
        )
    print(f"  speed-up 2 vs 1 workers: {figures['speedup_2_vs_1']:.2f}x")
    ok = "met" if figures["static50_wall_s"] <= 60.0 else "NOT MET"
    print(
        f"  full static campaign ({figures['static50_sorties']} sorties, "
        f"{figures['static50_workers']} workers): {figures['static50_wall_s']:.1f} s wall"
        f"  target <= 60 s: {ok}"
    )
    return 0


def run_dashboard_bench(tabs: int = 5, seconds: float = 6.0, as_json: bool = False) -> int:
    """The dashboard at 1x with ``tabs`` viewers open and visible at once (headless Chromium:
    no display needed), rendered camera, each with its 3D view, image plane and plots. Prints
    the share of real time the simulator keeps, the telemetry updates per second each viewer
    shows (redraws with new data), and the rate the server delivers to each."""
    import shutil
    import tempfile
    from pathlib import Path

    from playwright.sync_api import sync_playwright

    from .app.server import GroundStation
    from .app.session import SortieConfig
    from .scenario import with_changes

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        print("groundstation: error: the dashboard benchmark needs Debian's chromium")
        return 2
    args = [
        "--no-sandbox",
        "--enable-unsafe-swiftshader",
        "--disable-background-networking",
        "--disable-component-update",
        "--no-first-run",
    ]
    # a sortie long enough to measure at 1x: the SM target with a slow interceptor
    scenario = with_changes(load_scenario("sm-tailgate"), gains={"v_max": 4.5})
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        gs = GroundStation(port=0, data_dir=Path(tmp) / "gs", log_dir=Path(tmp) / "logs")
        gs.start_in_thread()
        try:
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=args)
            pages = [
                browser.new_page(viewport={"width": 1500, "height": 1000}) for _ in range(tabs)
            ]
            for page in tqdm(pages, desc="opening viewers", unit="viewer", leave=False):
                page.goto(gs.url())
                page.wait_for_selector("text=telemetry: live", timeout=30000)
            sess, hub = gs.session, gs.hub
            sess.start(SortieConfig(scenario, camera="rendered"))
            start_wall = time.perf_counter()
            time.sleep(2.0)
            upd0 = [pg.evaluate("window.peregrine.updates") for pg in pages]
            sent0, t0 = dict(hub.sent), time.perf_counter()
            time.sleep(seconds)
            elapsed = time.perf_counter() - t0
            upd1 = [pg.evaluate("window.peregrine.updates") for pg in pages]
            sent1 = dict(hub.sent)
            # over the whole sortie so far: a catch-up after a stall cannot flatter it
            share = sess.sim.time_s / (time.perf_counter() - start_wall)
            shown = [round((b - a) / elapsed, 1) for a, b in zip(upd0, upd1, strict=True)]
            delivered = sorted(round((sent1[k] - sent0.get(k, 0)) / elapsed, 1) for k in sent1)
            browser.close()
        finally:
            gs.stop()
    figures = {
        "viewers": tabs,
        "seconds": seconds,
        "sim_real_time_share": share,
        "updates_shown_hz": shown,
        "telemetry_delivered_hz": delivered,
    }
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0
    print(
        f"Dashboard benchmark: sm-tailgate (slowed), rendered camera, 1x, {tabs} viewers open "
        f"and visible (headless Chromium, {len(delivered)} telemetry subscribers), {seconds:.0f} s"
    )
    print(
        f"  simulator keeps {100 * share:.1f} % of real time  target >= 95 %: "
        f"{'met' if share >= 0.95 else 'NOT MET'}"
    )
    low = min(shown)
    print(
        f"  telemetry updates shown per viewer: {shown} Hz (median {statistics.median(shown):.1f})"
        f"  target >= 30 Hz in each: {'met' if low >= 30 else 'NOT MET'}"
    )
    print(f"  telemetry delivered to each viewer: {delivered} Hz")
    return 0


class _CountingFile:
    """A read-only file that counts the bytes read from it."""

    def __init__(self, f, counter: list[int]) -> None:
        self._f, self._counter = f, counter

    def read(self, n=-1):
        data = self._f.read(n)
        self._counter[0] += len(data)
        return data

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


def run_recording_bench(as_json: bool = False) -> int:
    """Recording cost, listing 200 sortie logs, and seeking in a 10-minute sortie."""
    import shutil
    import tempfile
    from pathlib import Path

    from .app.replay import ReplayPlayer
    from .recording import reader as log_reader
    from .recording import sink
    from .recording.reader import LogIndex
    from .scenario import with_changes

    figures: dict[str, object] = {"cores": len(os.sched_getaffinity(0))}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # warm up: imports, caches and the recording process
        Simulation(load_scenario("cv-top-to-bottom"), keep_records=False, log_dir=tmp / "w").run()

        # 1. what recording adds to a sortie's simulation time: the median, over many pairs
        # run back to back (plain, then recorded, same scenario and seed), of the ratio, so a
        # drift in the machine's load moves both halves of a pair alike. First as a sortie
        # runs (the recording process free to use another core), then with this process and
        # the recording process pinned to one core.
        def overhead(mode: str) -> tuple[float, int]:
            ratios = []
            for k in range(10):
                for name in ("cv-top-to-bottom", "sm-tailgate"):
                    sc = load_scenario(name)
                    t0 = time.perf_counter()
                    Simulation(sc, "png", k, mode, keep_records=False).run()
                    plain = time.perf_counter() - t0
                    t0 = time.perf_counter()
                    Simulation(sc, "png", k, mode, keep_records=False, log_dir=tmp / "o").run()
                    ratios.append((time.perf_counter() - t0) / plain)
            return statistics.median(ratios) - 1.0, len(ratios)

        proc = sink.recording_process()
        figures["recording_in"] = "a recording process" if proc else "this process"
        for mode in ("projected", "rendered"):
            figures[f"recording_overhead_{mode}"], n = overhead(mode)
            figures[f"recording_overhead_{mode}_pairs"] = n
        figures["where"] = _pin_one_core()
        if proc is not None and hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(proc.proc.pid, os.sched_getaffinity(0))
        for mode in ("projected", "rendered"):
            figures[f"recording_overhead_{mode}_one_core"], _ = overhead(mode)
        # 2. the Sorties list of 200 files
        src = next((tmp / "o").glob("*sm-tailgate*.mcap"))
        many = tmp / "many"
        many.mkdir()
        for i in range(200):
            shutil.copyfile(src, many / f"20261122T{i:06d}Z_sortie-{i:03d}_png.mcap")
        index = LogIndex(many)
        t0 = time.perf_counter()
        rows = index.list()
        figures["list_200_cold_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        index.list()
        figures["list_200_warm_s"] = time.perf_counter() - t0
        figures["list_200_rows"] = len(rows)
        figures["list_200_page_render_s"] = _sorties_page_render_s(many)
        # 3. seeking in a 10-minute sortie: the interceptor hovers (k_a = 0) and holds a
        # balloon 20 m ahead in view with its yaw loop until the 600 s timeout
        base = load_scenario("static-ahead-20m")
        long_sc = with_changes(
            base,
            duration_s=600.0,
            gains={"k_a": 0.0},
            interceptor=dataclasses.replace(base.interceptor, velocity_m_s=(0.0, 0.0, 0.0)),
        )
        t0 = time.perf_counter()
        sim = Simulation(long_sc, "png", 0, "rendered", keep_records=False, log_dir=tmp / "l")
        result = sim.run()
        figures["long_sortie_s"] = result.sim_time_s
        figures["long_sortie_outcome"] = result.outcome
        figures["long_record_wall_s"] = time.perf_counter() - t0
        path = sim.recorder.path
        size = path.stat().st_size
        player = ReplayPlayer(path)
        counter = [0]
        real_open = open
        log_reader.open = lambda p, mode="rb": _CountingFile(real_open(p, mode), counter)
        try:
            t0 = time.perf_counter()
            frame = player.frame_b64(300.0)
            figures["seek_s"] = time.perf_counter() - t0
        finally:
            del log_reader.open
        figures["seek_frame_found"] = frame is not None
        figures["long_file_mb"] = size / 1e6
        figures["seek_read_mb"] = counter[0] / 1e6
        figures["seek_read_fraction"] = counter[0] / size
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0
    print(f"Recording benchmark ({figures['cores']} cores; written by {figures['recording_in']})")
    for mode in ("projected", "rendered"):
        v = 100 * figures[f"recording_overhead_{mode}"]
        v1 = 100 * figures[f"recording_overhead_{mode}_one_core"]
        print(
            f"  recording adds {v:5.1f} % to a sortie's simulation time ({mode})  "
            f"target <= 10 %: {'met' if v <= 10 else 'NOT MET'}; "
            f"{v1:.1f} % with both processes pinned to one core"
        )
    page = figures["list_200_page_render_s"]
    print(
        f"  Sorties list of 200 files: {figures['list_200_cold_s']:.2f} s the first time (every "
        f"file's CRCs checked), {figures['list_200_warm_s'] * 1e3:.0f} ms after, page rendered "
        f"in {'—' if page is None else f'{page:.2f} s'}  target <= 1 s: "
        f"{'met' if page is not None and page <= 1.0 else 'see figures'}"
    )
    print(
        f"  seeking to 5:00 in a {figures['long_sortie_s'] / 60:.0f}-minute rendered sortie "
        f"({figures['long_file_mb']:.1f} MB): read {figures['seek_read_mb']:.2f} MB "
        f"({100 * figures['seek_read_fraction']:.1f} % of the file) in "
        f"{figures['seek_s'] * 1e3:.0f} ms, frame found: {figures['seek_frame_found']}"
    )
    return 0


def _sorties_page_render_s(log_dir) -> float | None:
    """Time from opening the Sorties page to its table showing every file (warm index)."""
    import shutil
    import tempfile
    from pathlib import Path

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        return None
    from playwright.sync_api import sync_playwright

    from .app.server import GroundStation

    with tempfile.TemporaryDirectory() as tmp:
        gs = GroundStation(port=0, data_dir=Path(tmp), log_dir=Path(log_dir))
        gs.start_in_thread()
        try:
            with sync_playwright() as p:
                browser = p.chromium.launch(
                    executable_path=chromium,
                    args=["--no-sandbox", "--disable-background-networking"],
                )
                page = browser.new_page()
                page.goto(gs.url())
                page.goto(gs.url().split("?")[0] + "sorties")  # warms the index
                page.wait_for_function(
                    "document.querySelectorAll('#logs tbody tr').length >= 200", timeout=60000
                )
                t0 = time.perf_counter()
                page.reload()
                page.wait_for_function(
                    "document.querySelectorAll('#logs tbody tr').length >= 200", timeout=60000
                )
                elapsed = time.perf_counter() - t0
                browser.close()
        finally:
            gs.stop()
    return elapsed


def _p99(xs: list[float]) -> float:
    return float(np.percentile(xs, 99))


def run_bench(repeat: int = 5, pin_one_core: bool = True, as_json: bool = False) -> int:
    where = _pin_one_core() if pin_one_core else "all cores"
    _real_time_factors("projected", 1)  # warm up imports and caches
    rtf_p = _real_time_factors("projected", repeat)
    rtf_r = _real_time_factors("rendered", max(1, repeat // 2))
    ticks = _tick_times_ms(repeat)
    detect_ms, render_ms, found = _frame_times_ms()
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    figures = {
        "where": where,
        "rtf_projected": statistics.median(rtf_p),
        "rtf_projected_min": min(rtf_p),
        "rtf_rendered": statistics.median(rtf_r),
        "rtf_rendered_min": min(rtf_r),
        "tick_median_ms": statistics.median(ticks),
        "tick_p99_ms": _p99(ticks),
        "ticks": len(ticks),
        "detector_median_ms": statistics.median(detect_ms),
        "detector_p99_ms": _p99(detect_ms),
        "render_median_ms": statistics.median(render_ms),
        "frames": len(detect_ms),
        "frames_with_detection": found,
        "peak_rss_mb": peak_mb,
    }
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0
    print(f"Peregrine core benchmark ({where}); scenarios {', '.join(BENCH_SCENARIOS)}")
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
            "control tick, median",
            "tick_median_ms",
            " ms",
            f"p99 {figures['tick_p99_ms']:.3f} ms over {len(ticks)} ticks",
        ),
        (
            "detector per 640x480 frame",
            "detector_median_ms",
            " ms",
            f"p99 {figures['detector_p99_ms']:.2f} ms, {len(detect_ms)} frames",
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


def run_sitl_bench(seconds: float = 20.0, as_json: bool = False) -> int:
    """``onboard run`` against ``groundstation sitl`` on loopback, one intercept
    (cv-top-to-bottom, started as soon as the target is seen), telemetry to a ground link
    this process drains: loop rate and jitter, capture-to-command latency, and the onboard
    process's CPU share and peak memory (from /proc)."""
    import socket
    import subprocess
    import sys
    import tempfile

    from onboard.link.px4 import MavLink

    socks = [socket.socket(socket.AF_INET, k) for k in (socket.SOCK_DGRAM,) * 2]
    socks.append(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
    for sock in socks:  # held together, so the three ports differ
        sock.bind(("127.0.0.1", 0))
    fc, gcs, cam = (sock.getsockname()[1] for sock in socks)
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
        )  # fmt: skip
        ground = MavLink(f"udpin:127.0.0.1:{gcs}", 255, 190)
        onboard = subprocess.Popen(
            [sys.executable, "-m", "onboard", "run", "--mavlink", f"udpout:127.0.0.1:{fc}",
             "--camera", f"sitl://127.0.0.1:{cam}", "--gcs", f"udpout:127.0.0.1:{gcs}",
             "--sitl-auto-start", "--duration", str(seconds), "--stats", str(stats_path)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        t0 = time.perf_counter()
        cpu = peak = None
        received = 0
        while onboard.poll() is None:
            received += len(ground.poll())
            c, m = _proc_cpu_s(onboard.pid), _proc_peak_rss_mb(onboard.pid)
            wall = time.perf_counter() - t0
            cpu, peak = (c, wall) if c is not None else cpu, m if m is not None else peak
            time.sleep(0.05)
        sitl.terminate()
        sitl.wait(10)
        ground.close()
        stats = json.loads(stats_path.read_text()) if stats_path.exists() else {}
        result = None
        for line in sitl_log.read_text().splitlines():
            if line.startswith("SITL_RESULT "):
                result = json.loads(line.removeprefix("SITL_RESULT "))
    cpu_s, wall_s = cpu if cpu else (None, None)
    figures = {
        "seconds": seconds,
        "loop_rate_hz": stats.get("rate_hz"),
        "jitter_p99_ms": stats.get("jitter_p99_ms"),
        "jitter_max_ms": stats.get("jitter_max_ms"),
        "tick_work_median_ms": stats.get("tick_work_median_ms"),
        "tick_work_p99_ms": stats.get("tick_work_p99_ms"),
        "overruns": stats.get("overruns"),
        "camera_delay_s": delay_s,
        "capture_to_command_median_ms": stats.get("latency_total_median_ms"),
        "beyond_camera_median_ms": stats.get("latency_beyond_camera_median_ms"),
        "beyond_camera_p99_ms": stats.get("latency_beyond_camera_p99_ms"),
        "detections_fused": stats.get("detections_fused"),
        "cpu_share_of_one_core": None if cpu_s is None else cpu_s / wall_s,
        "peak_rss_mb": peak,
        "ground_messages": received,
        "sitl_result": result,
    }
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0

    def f(x, d=2):
        return "—" if x is None else f"{x:.{d}f}"

    print(f"onboard run vs groundstation sitl, {seconds:g} s, one cv-top-to-bottom intercept")
    print(f"  loop rate {f(figures['loop_rate_hz'], 1)} Hz  target 200")
    print(
        f"  period jitter p99 {f(figures['jitter_p99_ms'])} ms (max {f(figures['jitter_max_ms'])})"
        "  target <= 2 ms"
    )
    print(
        f"  tick work median {f(figures['tick_work_median_ms'])} ms, p99 "
        f"{f(figures['tick_work_p99_ms'])} ms, overruns {figures['overruns']}"
    )
    print(
        f"  capture-to-command median {f(figures['capture_to_command_median_ms'], 1)} ms, of "
        f"which beyond the camera's own delay ({1000 * delay_s:.0f} ms): median "
        f"{f(figures['beyond_camera_median_ms'])} ms, p99 {f(figures['beyond_camera_p99_ms'])} ms"
        "  target <= 10 ms"
    )
    print(
        f"  onboard process: CPU {f(100 * figures['cpu_share_of_one_core'] if cpu_s else None, 0)}"
        f" % of one core, peak memory {f(peak, 0)} MB  target <= 300 MB"
    )
    if result:
        print(f"  intercept: {result['outcome']}, miss {result['miss_m']:.3f} m")
    return 0
