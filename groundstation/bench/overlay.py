"""``groundstation bench --overlay``: the Sorties overlay page with N recorded sorties (20 by
default), in headless Chromium: how long it takes to open (the request, the plots and the
trajectories drawn; the first time and again with the server's per-file cache warm) and how
many scrub frames a second it draws while the cursor is dragged through every plot."""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

from onboard.enums import GuidanceLaw

from ..scenario import load_scenario

SCRUB_S = 3.0


def _fly(log_dir: Path, n: int) -> list[str]:
    """N sorties of cv-top-to-bottom (laws, seeds and K_y varied), recorded; their names."""
    from onboard.gains import Gains

    from ..recording.writer import SortieRecorder
    from ..sim.simulation import Simulation

    names = []
    scenario = load_scenario("cv-top-to-bottom")
    for k in range(n):
        rec = SortieRecorder(log_dir)
        gains = Gains(K_y=2.0 + 0.25 * (k % 8))
        law = (GuidanceLaw.PNG.value, GuidanceLaw.PG.value)[k % 2]
        Simulation(scenario, law, k, "projected", gains, keep_records=False, observers=(rec,)).run()
        names.append(rec.path.name)
    return names


def run_overlay_bench(n: int = 20, as_json: bool = False) -> int:
    from playwright.sync_api import sync_playwright

    from ..app.server import GroundStation

    work = Path(tempfile.mkdtemp(prefix="peregrine-overlay-"))
    try:
        names = _fly(work / "logs", n)
        gs = GroundStation(port=0, data_dir=work, log_dir=work / "logs", scene_port=None)
        gs.start_in_thread()
        chromium = shutil.which("chromium") or shutil.which("chromium-browser")
        try:
            with sync_playwright() as p:
                b = p.chromium.launch(
                    executable_path=chromium, args=["--no-sandbox", "--enable-unsafe-swiftshader"]
                )
                page = b.new_page(viewport={"width": 1500, "height": 1100})
                url = gs.url().split("?")[0] + "overlay?names=" + ",".join(names)
                page.goto(gs.url())  # the access cookie
                opened = []
                for _ in range(2):  # cold, then with the server's cache warm
                    t0 = time.perf_counter()
                    page.goto(url)
                    page.wait_for_function("window.peregrine.openedMs !== null", timeout=120000)
                    opened.append(
                        {
                            "wall_s": time.perf_counter() - t0,
                            "page_ms": page.evaluate("window.peregrine.openedMs"),
                            "fetch_ms": page.evaluate("window.peregrine.fetchMs"),
                        }
                    )
                fps = page.evaluate(
                    """(secs) => new Promise((done) => {
                      const s = document.getElementById('ov-scrub'), lo = +s.min, hi = +s.max;
                      const d0 = window.peregrine.drawn, t0 = performance.now();
                      const step = () => {
                        const el = performance.now() - t0;
                        const drawn = window.peregrine.drawn - d0;
                        if (el > secs * 1000) return done(drawn / (el / 1000));
                        s.value = lo + (hi - lo) * ((el / 1000) % 1);
                        s.dispatchEvent(new Event('input'));
                        requestAnimationFrame(step);
                      };
                      requestAnimationFrame(step);
                    })""",
                    SCRUB_S,
                )
                b.close()
        finally:
            gs.stop()
    finally:
        shutil.rmtree(work, ignore_errors=True)
    out = {"sorties": n, "open_cold": opened[0], "open_warm": opened[1], "scrub_fps": fps}
    if as_json:
        print(json.dumps(out))
    else:
        print(f"overlay of {n} sorties (headless Chromium, this machine):")
        for k in ("open_cold", "open_warm"):
            o = out[k]
            page_s = o["page_ms"] / 1000
            fetch_s = o["fetch_ms"] / 1000
            print(
                f"  {k}: {o['wall_s']:.2f} s to load and draw ({page_s:.2f} s in the page, "
                f"{fetch_s:.2f} s of it the request)"
            )
        print(f"  scrub: {fps:.1f} frames/s over {SCRUB_S:g} s of dragging")
    return 0
