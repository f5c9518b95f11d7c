"""``groundstation bench --dashboard``: the dashboard served to several browser tabs."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from ..scenario import load_scenario


def _virtual_display():
    """A private Xvfb display for a headed browser (the dashboard benchmark opens real tabs in
    one real window, as an operator has them). Returns (process, env) or (None, env)."""
    import shutil
    import subprocess

    env = dict(os.environ)
    if env.get("DISPLAY"):
        return None, env
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        return None, None
    for n in range(90, 140):
        if os.path.exists(f"/tmp/.X11-unix/X{n}") or os.path.exists(f"/tmp/.X{n}-lock"):
            continue
        proc = subprocess.Popen(
            [xvfb, f":{n}", "-screen", "0", "1600x1100x24", "-nolisten", "tcp"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for _ in range(50):
            if os.path.exists(f"/tmp/.X11-unix/X{n}"):
                env["DISPLAY"] = f":{n}"
                return proc, env
            time.sleep(0.1)
        proc.terminate()
    return None, None


def run_dashboard_bench(tabs: int = 5, seconds: float = 6.0, as_json: bool = False) -> int:
    """The dashboard at 1x with ``tabs`` tabs connected, rendered camera, as an operator has
    them: real tabs in one real browser window (headed Chromium on a virtual display), one in
    front. Prints the share of real time the simulator keeps, how often the front tab's views
    refresh, how often every tab receives telemetry, and the background tabs' refresh (which
    the browser throttles)."""
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
    xvfb, env = _virtual_display()
    if env is None:
        print(
            "groundstation: error: the dashboard benchmark needs a display or Xvfb "
            "(apt-get install xvfb)"
        )
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
    try:
        with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
            gs = GroundStation(port=0, data_dir=Path(tmp) / "gs", log_dir=Path(tmp) / "logs")
            gs.start_in_thread()
            try:
                ctx = p.chromium.launch_persistent_context(
                    Path(tmp) / "profile",
                    executable_path=chromium,
                    headless=False,
                    args=args,
                    env=env,
                    viewport={"width": 1500, "height": 1000},
                )
                pages = [ctx.pages[0] if ctx.pages else ctx.new_page()]
                pages += [ctx.new_page() for _ in range(tabs - 1)]
                for page in pages:
                    page.goto(gs.url())
                    page.wait_for_selector("text=telemetry: live", timeout=30000)
                front = pages[0]
                front.bring_to_front()
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
                refresh = [round((b - a) / elapsed, 1) for a, b in zip(upd0, upd1, strict=True)]
                delivered = sorted(round((sent1[k] - sent0.get(k, 0)) / elapsed, 1) for k in sent1)
                ctx.close()
            finally:
                gs.stop()
    finally:
        if xvfb is not None:
            xvfb.terminate()
    figures = {
        "tabs": tabs,
        "seconds": seconds,
        "sim_real_time_share": share,
        "front_tab_refresh_hz": refresh[0],
        "background_tabs_refresh_hz": refresh[1:],
        "telemetry_delivered_hz": delivered,
    }
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0
    print(
        f"Dashboard benchmark: sm-tailgate (slowed), rendered camera, 1x, {tabs} tabs in one "
        f"browser window ({len(delivered)} telemetry subscribers), {seconds:.0f} s"
    )
    print(
        f"  simulator keeps {100 * share:.1f} % of real time  target >= 95 %: "
        f"{'met' if share >= 0.95 else 'NOT MET'}"
    )
    print(
        f"  front tab's views refresh at {refresh[0]:.1f} Hz  target >= 20 Hz: "
        f"{'met' if refresh[0] >= 20 else 'NOT MET'}"
    )
    print(f"  telemetry delivered to every tab: {delivered} Hz")
    print(f"  background tabs refresh (throttled by the browser): {refresh[1:]} Hz")
    return 0
