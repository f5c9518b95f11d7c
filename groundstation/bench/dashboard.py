"""``groundstation bench --dashboard``: the dashboard served to several viewers at once, in
headless Chromium (no display needed)."""

from __future__ import annotations

import json
import os
import statistics
import time
from pathlib import Path

from tqdm import tqdm

from ..scenario import load_scenario

_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01


def _cpu_s(stat_path: str) -> float | None:
    """User + system CPU seconds of a process or thread (Linux /proc), None if unreadable."""
    try:
        with open(stat_path) as f:
            fields = f.read().rpartition(")")[2].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) * _TICK_S


def _cpu_sample(sim_tid: int | None) -> dict[str, float]:
    """CPU seconds so far: this process, its simulator thread, its child processes (Playwright's
    driver and Chromium: pages, 3D views, GPU and browser processes), and the whole machine
    (Linux /proc; empty elsewhere)."""
    if not os.path.isdir("/proc/self/task"):
        return {}
    me = os.getpid()
    out = {"station": _cpu_s("/proc/self/stat") or 0.0, "browser": 0.0}
    if sim_tid is not None:
        out["simulator"] = _cpu_s(f"/proc/self/task/{sim_tid}/stat") or 0.0
    parent: dict[int, int] = {}
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/stat") as f:
                parent[int(pid)] = int(f.read().rpartition(")")[2].split()[1])
        except (OSError, ValueError, IndexError):
            continue
    for pid in parent:
        up, hops = parent.get(pid), 0
        while up and up != me and hops < 64:
            up, hops = parent.get(up), hops + 1
        if up == me:
            out["browser"] += _cpu_s(f"/proc/{pid}/stat") or 0.0
    try:
        with open("/proc/stat") as f:
            ticks = [int(x) for x in f.readline().split()[1:]]
        out["machine"] = (sum(ticks) - ticks[3] - ticks[4]) * _TICK_S  # all but idle, iowait
    except (OSError, ValueError, IndexError):
        pass
    return out


def _percent_of_a_core(before: dict, after: dict, elapsed_s: float) -> dict[str, float]:
    """CPU used between two :func:`_cpu_sample` readings, in % of one core."""
    return {k: round(100 * (after[k] - before[k]) / elapsed_s, 1) for k in after if k in before}


def run_dashboard_bench(
    tabs: int = 5, seconds: float = 6.0, as_json: bool = False, idle_seconds: float = 4.0
) -> int:
    """The dashboard at 1x with ``tabs`` viewers open and visible at once (headless Chromium:
    no display needed), rendered camera, each with its 3D view, image plane and plots. First
    the CPU the open viewers cost with no sortie (``idle_seconds``). Then it prints
    the share of real time the simulator keeps and, per viewer, the telemetry messages per
    second the server sent it (delivered), its page received, applied to the plots' series and
    readouts (applied) and showed in a redrawn frame (painted); how many snapshots the session
    published at its slower rate (the simulator starved); the CPU the station, its
    simulator thread, the browser and other processes used in the window; and the load
    average, which other work on the machine raises."""
    import shutil
    import tempfile

    from playwright.sync_api import sync_playwright

    from ..app.server import GroundStation
    from ..app.session_config import SortieConfig
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
    load_before = os.getloadavg()[0]
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
            time.sleep(3.0)  # the viewers' 3D views load and fit their cameras
            idle0, idle_t0 = _cpu_sample(None), time.perf_counter()
            time.sleep(idle_seconds)
            idle1, idle_elapsed = _cpu_sample(None), time.perf_counter() - idle_t0
            sess.start(SortieConfig(scenario, camera="rendered"))
            start_wall = time.perf_counter()
            time.sleep(2.0)
            # each viewer's counts against its own clock, read in one call: on a loaded machine
            # reading five pages one after another takes seconds, which a shared wall-clock
            # window would wrongly count for the pages read last
            probe = (
                "[performance.now(), window.peregrine.received || 0,"
                " window.peregrine.applied ?? null, window.peregrine.updates]"
            )
            sim_tid = getattr(getattr(sess, "_thread", None), "native_id", None)
            behind0 = sess.published_behind
            sent0, pub0, t0 = dict(hub.sent), hub.published, time.perf_counter()
            cpu0 = _cpu_sample(sim_tid)
            c0 = [pg.evaluate(probe) for pg in pages]
            time.sleep(seconds)
            sent1, pub1, elapsed = dict(hub.sent), hub.published, time.perf_counter() - t0
            behind1 = sess.published_behind
            cpu1 = _cpu_sample(sim_tid)
            # over the whole sortie so far: a catch-up after a stall cannot flatter it
            share = sess.sim.time_s / (time.perf_counter() - start_wall)
            c1 = [pg.evaluate(probe) for pg in pages]
            scene = [f for f in pages[0].frames if "/viser/" in f.url]
            software = (
                scene[0].evaluate("window.peregrineScene ? window.peregrineScene.software : null")
                if scene
                else None
            )
            browser.close()
        finally:
            gs.stop()
    load_after = os.getloadavg()[0]

    def rate(k: int) -> list[float | None]:
        out = []
        for a, b in zip(c0, c1, strict=True):
            dt = max((b[0] - a[0]) / 1000.0, 1e-3)
            out.append(None if a[k] is None or b[k] is None else round((b[k] - a[k]) / dt, 1))
        return out

    received, applied, painted = rate(1), rate(2), rate(3)
    delivered = sorted(round((sent1[k] - sent0.get(k, 0)) / elapsed, 1) for k in sent1)
    figures = {
        "viewers": tabs,
        "seconds": seconds,
        "sim_real_time_share": share,
        "snapshots_published_hz": round((pub1 - pub0) / elapsed, 1),
        # snapshots the session published at its slower rate (the simulator starved: more
        # than BEHIND_TOLERANCE_S behind the clock and not catching up)
        "snapshots_published_behind": behind1 - behind0,
        "telemetry_delivered_hz": delivered,
        "received_hz": received,
        "applied_hz": applied,
        "painted_hz": painted,
        "software_webgl": software,
        # CPU used in the window, in % of one core: the ground station (this process), its
        # simulator thread, the browser (Chromium's pages, 3D views, GPU and browser processes
        # and Playwright's driver), and the whole machine
        "cpu_percent_of_a_core": _percent_of_a_core(cpu0, cpu1, elapsed),
        "load_average_before_after": [round(load_before, 2), round(load_after, 2)],
        # the same with the viewers open and no sortie (an idle session)
        "idle_cpu_percent_of_a_core": _percent_of_a_core(idle0, idle1, idle_elapsed),
    }
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0
    print(
        f"Dashboard benchmark: sm-tailgate (slowed), rendered camera, 1x, {tabs} viewers open "
        f"and visible (headless Chromium, {len(delivered)} telemetry subscribers, "
        f"{'software' if software else 'hardware' if software is not None else 'unknown'} "
        f"WebGL), {seconds:.0f} s, load average {load_before:.1f} before, {load_after:.1f} after "
        f"({os.cpu_count()} CPUs)"
    )
    print(
        f"  simulator keeps {100 * share:.1f} % of real time  target >= 95 %: "
        f"{'met' if share >= 0.95 else 'NOT MET'}"
    )

    def line(name: str, values: list[float | None], target: bool = False) -> None:
        known = [v for v in values if v is not None]
        text = f"  {name:<44s}{values} Hz"
        if known:
            text += f" (median {statistics.median(known):.1f})"
        if target:
            ok = len(known) == len(values) and min(known) >= 30
            text += f"  target >= 30 Hz in each: {'met' if ok else 'NOT MET'}"
        print(text)

    idle = figures["idle_cpu_percent_of_a_core"]
    if "browser" in idle:
        print(
            f"  no sortie, {tabs} viewers open: CPU browser {idle['browser']:.0f} %, station "
            f"{idle.get('station', 0.0):.0f} % of one core"
        )
    line("published by the session (one for all):", [figures["snapshots_published_hz"]])
    print(
        f"  {'':<44s}{figures['snapshots_published_behind']} of {pub1 - pub0} at the slower"
        " rate (the simulator starved: > 0.1 s behind the clock, not catching up)"
    )
    line("delivered by the server to each viewer:", list(delivered))
    line("received by each page:", received)
    line("applied to each page's plots and readouts:", applied, target=True)
    line("painted (frames showing new data) per page:", painted)
    cpu = dict(figures["cpu_percent_of_a_core"])
    if "machine" in cpu:
        cpu["other processes"] = round(
            cpu.pop("machine") - cpu.get("station", 0.0) - cpu.get("browser", 0.0), 1
        )
    if cpu:
        print(
            "  CPU in the window, % of one core: "
            + ", ".join(f"{k} {v:.0f}" for k, v in cpu.items())
            + " (the simulator thread is part of the station)"
        )
    return 0
