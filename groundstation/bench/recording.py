"""``groundstation bench --recording``: what recording costs a sortie, listing 200 logs,
seeking in a 10-minute sortie."""

from __future__ import annotations

import dataclasses
import json
import os
import statistics
import time
from pathlib import Path

from ..scenario import load_scenario
from ..sim.simulation import Simulation
from .core import _pin_one_core


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

    from ..app.replay import ReplayPlayer
    from ..recording import reader as log_reader
    from ..recording import sink
    from ..recording.reader import LogIndex
    from ..recording.writer import SortieRecorder as Rec
    from ..scenario import with_changes

    figures: dict[str, object] = {"cores": len(os.sched_getaffinity(0))}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # warm up: imports, caches and the recording process
        Simulation(
            load_scenario("cv-top-to-bottom"), keep_records=False, observers=[Rec(tmp / "w")]
        ).run()

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
                    Simulation(
                        sc, "png", k, mode, keep_records=False, observers=[Rec(tmp / "o")]
                    ).run()
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
        rec = Rec(tmp / "l")
        sim = Simulation(long_sc, "png", 0, "rendered", keep_records=False, observers=[rec])
        result = sim.run()
        figures["long_sortie_s"] = result.sim_time_s
        figures["long_sortie_outcome"] = result.outcome
        figures["long_record_wall_s"] = time.perf_counter() - t0
        path = rec.path
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

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        return None
    from playwright.sync_api import sync_playwright

    from ..app.server import GroundStation

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
