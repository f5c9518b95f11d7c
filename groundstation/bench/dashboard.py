"""``groundstation bench --dashboard``: the dashboard served to several viewers at once, in
headless Chromium (no display needed)."""

from __future__ import annotations

import json
import statistics
import time
from pathlib import Path

from tqdm import tqdm

from ..scenario import load_scenario


def run_dashboard_bench(tabs: int = 5, seconds: float = 6.0, as_json: bool = False) -> int:
    """The dashboard at 1x with ``tabs`` viewers open and visible at once (headless Chromium:
    no display needed), rendered camera, each with its 3D view, image plane and plots. Prints
    the share of real time the simulator keeps, the telemetry updates per second each viewer
    shows (redraws with new data), and the rate the server delivers to each."""
    import shutil
    import tempfile

    from playwright.sync_api import sync_playwright

    from ..app.server import GroundStation
    from ..app.session import SortieConfig
    from ..scenario import with_changes

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
                page.wait_for_selector("text=telemetry: live", timeout=120000)
            sess, hub = gs.session, gs.hub
            sess.start(SortieConfig(scenario, camera="rendered"))
            start_wall = time.perf_counter()
            time.sleep(2.0)
            # each viewer's count against its own clock, read in one call: on a loaded machine
            # reading five pages one after another takes seconds, which a shared wall-clock
            # window would wrongly count for the pages read last
            probe = "[window.peregrine.updates, performance.now()]"
            sent0, t0 = dict(hub.sent), time.perf_counter()
            upd0 = [pg.evaluate(probe) for pg in pages]
            time.sleep(seconds)
            sent1, elapsed = dict(hub.sent), time.perf_counter() - t0
            # over the whole sortie so far: a catch-up after a stall cannot flatter it
            share = sess.sim.time_s / (time.perf_counter() - start_wall)
            upd1 = [pg.evaluate(probe) for pg in pages]
            shown = [
                round((b[0] - a[0]) / max((b[1] - a[1]) / 1000.0, 1e-3), 1)
                for a, b in zip(upd0, upd1, strict=True)
            ]
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
