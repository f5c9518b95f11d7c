"""What the dashboard's browser tests share: opening the page, flying a sortie through the
session, the API as the page calls it, and putting the session back to the defaults. The
``page`` fixture (a page whose script errors fail the test) is in browser_support."""

from __future__ import annotations

import json
import time
import urllib.request

from groundstation.app.session import SortieConfig
from groundstation.recording.reader import inspect_log
from groundstation.scenario import load_scenario


def base(station) -> str:
    return station.url().split("?")[0]


def goto(page, station, query: str = "") -> None:
    page.goto(station.url() + query)
    page.wait_for_selector("text=telemetry: live", timeout=15000)
    page.wait_for_function("document.querySelectorAll('#gains input').length > 5")
    page.wait_for_function("window.peregrine.plots.length >= 5", timeout=10000)


def fly(station, scenario="cv-top-to-bottom", law="png", speed="max", camera="projected") -> str:
    """Fly a whole sortie through the session; the name of its recording."""
    s = station.session
    s.start(SortieConfig(load_scenario(scenario), law, 0, camera, speed))
    name = s.recording["file"]
    deadline = time.monotonic() + 120
    while s.state != "finished":
        assert time.monotonic() < deadline, "the sortie did not finish"
        time.sleep(0.05)
    return name


def status(station) -> dict:
    return station.session.status()


def plot_t(page, k=0):
    return page.evaluate(f"window.peregrine.plots[{k}].data[0]")


def api(station, method, path, body=None):
    req = urllib.request.Request(base(station) + path.lstrip("/"), method=method)
    req.add_header("Cookie", f"peregrine_token={station.token}")
    data = None if body is None else json.dumps(body).encode()
    if data is not None:
        req.add_header("Content-Type", "application/json")
    with urllib.request.urlopen(req, data, timeout=10) as r:
        return json.loads(r.read())


def wait_state(station, state, timeout=60):
    deadline = time.monotonic() + timeout
    while station.session.state != state:
        assert time.monotonic() < deadline, f"the sortie never became {state}"
        time.sleep(0.05)


def clean(station):
    """Nothing on screen, the defaults without edits."""
    s = station.session
    s.reset()
    s.set_gains(load_scenario("cv-top-to-bottom").gains_obj(), "defaults")


def recorded_gains(station, name) -> dict:
    return json.loads(inspect_log(station.log_dir / name).metadata["sortie"]["gains"])
