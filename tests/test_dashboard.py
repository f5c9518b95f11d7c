"""The dashboard shows true numbers and curves after what an operator does: the gain
flown after Start, the plotted series after a backward seek, the replay speed actually used, the
re-fly overlay and its legend, plots restored after a reload, the recording banner after a write
error. One ground station and one headless chromium serve every test of this module."""

import itertools
import json
import re
import shutil
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from groundstation.app.numbers import fmt_num
from groundstation.app.session import SortieConfig
from groundstation.scenario import load_scenario

from .as_written import load_as_written
from .browser_support import needs_chromium

pytestmark = needs_chromium


@pytest.fixture
def page(station, browser):
    pg = browser.new_page(viewport={"width": 1500, "height": 1100})
    pg.errors = []
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    yield pg
    errors = pg.errors
    pg.close()
    assert not errors, errors


def base(station) -> str:
    return station.url().split("?")[0]


def goto(page, station, query: str = "") -> None:
    page.goto(station.url() + query)
    page.wait_for_selector("text=telemetry: live", timeout=15000)
    page.wait_for_function("document.querySelectorAll('#gains input').length > 5")
    page.wait_for_function("window.peregrine.plots.length >= 5", timeout=10000)


def fly(station, scenario="cv-top-to-bottom", law="png", speed="max") -> str:
    """Fly a whole sortie through the session; the name of its recording."""
    s = station.session
    s.start(SortieConfig(load_scenario(scenario), law, 0, "projected", speed))
    name = s.recording["file"]
    deadline = time.monotonic() + 60
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


# ---------------------------------------------------------------------- B14: sorties page
def test_sorties_page_says_when_there_is_nothing_to_show(station, page):
    page.goto(station.url())
    page.goto(base(station) + "sorties")
    page.wait_for_selector("#empty:not([hidden])")
    assert page.text_content("#empty").startswith("No recorded sorties yet.")
    assert page.text_content("#count") == "0 of 0 sorties"


# ---------------------------------------------------------------------- A1: gains at Start
def test_gain_edited_between_sorties_is_flown_at_start(station, page):
    station.session.reset()
    station.session.set_gains(station.session.default_gains())
    goto(page, station)
    page.fill('#gains input[data-gain="K_y"]', "4")
    page.click("#btn-apply-gains")
    page.wait_for_function("document.querySelector('#st-gains').textContent.includes('K_y* 3→4')")
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "1")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap.t > 0.3 && window.peregrine.snap.status.state"
                           " === 'running'", timeout=15000)  # fmt: skip
    assert station.session.sim.loop.gains.K_y == 4.0  # the edit flies (main: back to 3)
    assert page.input_value('#gains input[data-gain="K_y"]') == "4"
    assert "edited" in page.get_attribute('#gains tr[data-gain="K_y"]', "class")
    assert "K_y* 3→4" in page.text_content("#st-gains")

    # a scenario that carries its own gains replaces the edits, and the page says so
    page.select_option("#scenario", "outdoor-static")
    page.click("#btn-start")
    page.wait_for_function(  # the note names the edit the scenario's gains replaced
        "document.querySelector('#gains-note').textContent.includes('carries its own gains')"
        " && document.querySelector('#gains-note').textContent.includes('K_y')"
    )
    assert station.session.sim.loop.gains.K_y == 3.0
    assert station.session.sim.loop.gains.a_max == load_scenario("outdoor-static").gains["a_max"]
    page.wait_for_function(  # the header follows with the next snapshot
        "document.querySelector('#st-gains').textContent"
        ".startsWith('gains: scenario outdoor-static')"
    )
    page.wait_for_function(
        "document.querySelector('#gains input[data-gain=\"K_y\"]').value === '3'"
    )
    station.session.reset()


# ---------------------------------------------------------------------- A2, A7, A9: replay plots
def test_replay_plots_show_the_whole_sortie_and_a_backward_seek_moves_only_the_cursor(
    station, page
):
    name = fly(station)
    goto(page, station, "")
    page.goto(base(station) + "sorties")
    page.locator(f'#logs tbody tr[data-name="{name}"]').locator("button[data-act=open]").click()
    page.wait_for_selector("#replay-panel:not([hidden])", timeout=10000)
    page.wait_for_function(
        "window.peregrine.plots.length >= 5 && window.peregrine.plots[0].data[0].length > 50",
        timeout=10000,
    )
    series = api(station, "GET", f"/api/logs/{name}/series")
    duration = status(station)["replay"]["duration_s"]
    # before any Play the plots hold the whole recorded sortie
    t = plot_t(page)
    assert t == series["t_s"] and t[-1] == pytest.approx(duration, abs=0.1)
    speed_plot = page.evaluate("window.peregrine.plots[1].data")
    assert speed_plot[1] == series["columns"]["speed_m_s"]

    for target in (4.0, 1.5):  # forward, then back: data unchanged, the cursor follows
        page.eval_on_selector(
            "#rp-scrub",
            "(el, v) => { el.value = v; el.dispatchEvent(new Event('input'));"
            " el.dispatchEvent(new Event('change')); }",
            target,
        )
        page.wait_for_function(f"Math.abs(window.peregrine.cursorT - {target}) < 0.02",
                               timeout=10000)  # fmt: skip
        assert plot_t(page) == series["t_s"]  # nothing cleared, nothing invented
    # the legend shows the recorded value at the cursor time
    i = next(k for k, x in enumerate(series["t_s"]) if x >= 1.5 - 1e-6)
    shown = page.text_content(".plot:nth-child(2) .u-legend .u-series:nth-child(2) .u-value")
    assert float(shown) == pytest.approx(series["columns"]["speed_m_s"][i], abs=0.01)

    # A7: "v normal to LOS" is computed from the recorded frame
    vn = series["columns"]["normal_vel_m_s"]
    assert sum(v is not None for v in vn) > 0.9 * len(vn)
    assert page.evaluate("window.peregrine.snap.normal_vel_m_s") is not None
    assert max(v for v in vn if v is not None) > 0.5
    # A9: file names keep their case
    assert page.eval_on_selector("#rp-file", "e => getComputedStyle(e).textTransform") == "none"
    assert name in page.text_content("#rp-file")


# ---------------------------------------------------------------------- A3: replay speed
def test_replay_runs_at_the_speed_the_control_shows(station, page):
    name = fly(station, speed="max")  # the last sortie flew at max
    api(station, "POST", "/api/replay/open", {"name": name})
    goto(page, station)
    page.wait_for_selector("#replay-panel:not([hidden])")
    assert page.input_value("#speed") == "1"
    assert status(station)["speed"] == "1"
    page.click("#rp-play")
    t0 = time.monotonic()
    page.wait_for_function("window.peregrine.snap.status.replay.t_s > 0.05")
    time.sleep(1.0)
    played = status(station)["replay"]["t_s"]
    wall = time.monotonic() - t0
    assert 0.6 * wall < played < 1.3 * wall + 0.1, (played, wall)  # main: 50x, at the end
    assert status(station)["replay"]["speed_x"] == 1.0
    page.select_option("#speed", "2")
    page.wait_for_function("window.peregrine.snap.status.replay.speed_x === 2")
    page.click("#rp-play")  # pause


# ---------------------------------------------------------------------- A4, A5: re-fly, compare
def test_refly_runs_at_1x_with_the_old_sortie_overlaid_and_a_legend(station, page):
    name = fly(station, law="png")
    page.goto(station.url())
    page.goto(base(station) + "sorties")
    page.select_option("#refly-law", "pg")
    row = page.locator(f'#logs tbody tr[data-name="{name}"]')
    row.locator("button[data-act=refly]").click()
    page.click("#refly-go")  # the form's gains as recorded
    page.wait_for_url(re.compile(r"compare="))
    page.wait_for_function("window.peregrine.plots.length >= 5", timeout=10000)
    st = status(station)
    assert st["compare"]["file"] == name and st["compare"]["law"] == "png"
    assert st["law"] == "pg" and st["speed"] == "1" and st["state"] == "running"
    t0, w0 = status(station)["time_s"], time.monotonic()
    time.sleep(1.0)
    rate = (status(station)["time_s"] - t0) / (time.monotonic() - w0)
    assert 0.5 < rate < 1.3, rate  # at 1x it can be watched (main: max, over at once)
    page.wait_for_selector("#cmp-legend:not([hidden])")
    # B's gains are told against A's, which the page reads from /api/gains
    page.wait_for_function(
        "document.querySelector('#cmp-legend').textContent.includes('gains: same as A')",
        timeout=10000,
    )
    legend = page.text_content("#cmp-legend")
    assert "A (solid)" in legend and "· pg" in legend
    assert f"B (dashed): {name}" in legend and "png" in legend and "gains: same as A" in legend
    # every time plot carries both sorties, B in colours of its own
    labels = page.evaluate("window.peregrine.plots.map(u => u.series.map(s => s.label))")
    for lab in labels[:4]:
        assert any(x.endswith("· A") for x in lab) and any(x.endswith("· B") for x in lab)
    strokes = page.evaluate("window.peregrine.plots[3].series.slice(1).map(s => s._stroke)")
    assert len(set(strokes)) == 2
    b_range = page.evaluate("window.peregrine.plots[3].data[2].filter(v => v !== null).length")
    assert b_range > 50
    assert st["compare"]["file"] in page.text_content("#cmp-legend")
    reflown = station.session.recording["file"]
    station.session.reset()
    # B14: the Sorties page shows the lineage and the columns an operator sorts by
    page.goto(base(station) + "sorties")
    row = page.locator(f'#logs tbody tr[data-name="{reflown}"]')
    assert f"re-flown from {name}" in row.text_content()
    cells = row.locator("td").all_text_contents()
    assert cells[1:5] == ["cv-top-to-bottom", "pg", "projected", "0"]
    page.fill("#filter", "no-such-sortie")
    assert page.text_content("#empty") == 'No sortie matches "no-such-sortie".'


def test_compare_named_in_the_url_is_overlaid(station, page):
    a = fly(station, law="png")
    b = fly(station, law="pg")
    api(station, "POST", "/api/replay/open", {"name": a})
    goto(page, station, f"&compare={b}")
    page.wait_for_function(
        f"document.querySelector('#cmp-legend').textContent.includes('{b}')", timeout=10000
    )
    assert status(station)["compare"]["file"] == b
    assert status(station)["replay"]["compare"] == b


# ---------------------------------------------------------------------- A6: reload
def test_reload_restores_the_sortie_so_far_and_the_controls_in_force(station, page):
    station.session.reset()
    goto(page, station)
    page.select_option("#law", "pg")
    page.fill("#seed", "3")
    page.select_option("#speed", "1")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap.t > 2.0", timeout=15000)
    page.reload()
    page.wait_for_selector("text=telemetry: live")
    page.wait_for_function(
        "window.peregrine.plots.length >= 5 && window.peregrine.plots[3].data[0].length > 40",
        timeout=10000,
    )
    t = plot_t(page, 3)
    assert t[0] < 0.1 and t[-1] > 2.0  # the sortie from its start, not from the reload
    rng = page.evaluate("window.peregrine.plots[3].data[1]")
    assert rng[0] == pytest.approx(station.session.series()["columns"]["range_m"][0])
    assert page.input_value("#law") == "pg"  # what flies, not the page's default
    assert page.input_value("#seed") == "3"
    assert page.input_value("#speed") == "1"
    station.session.reset()


def test_reload_in_replay_keeps_the_position_and_the_plots(station, page):
    name = fly(station)
    api(station, "POST", "/api/replay/open", {"name": name})
    api(station, "POST", "/api/replay/seek", {"t_s": 2.0})
    goto(page, station)
    page.wait_for_function("Math.abs(window.peregrine.cursorT - 2.0) < 0.02", timeout=10000)
    assert float(page.input_value("#rp-scrub")) == pytest.approx(2.0)
    assert plot_t(page)[-1] > 5.0


# ---------------------------------------------------------------------- A8, A9: banner, status
def test_recording_file_and_write_error_show_as_a_banner(station, page):
    goto(page, station)
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "1")
    page.click("#btn-start")
    page.wait_for_function("document.querySelector('#rec-banner').textContent"
                           ".startsWith('Recording to')")  # fmt: skip
    rec = station.session.recording
    assert rec["file"] in page.text_content("#rec-banner")

    def disk_full():
        station.session.recorder._fail(OSError(28, "No space left on device"))

    station.session.submit(disk_full)
    page.wait_for_selector("#rec-banner.err", timeout=5000)
    text = page.text_content("#rec-banner")
    assert "No space left on device" in text and "no longer recorded" in text
    station.session.reset()


def test_status_line_follows_the_sortie_to_its_end(station, page):
    goto(page, station)
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "max")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap.status.state === 'finished'", timeout=30000)
    page.wait_for_function("document.querySelector('#sim-msg').textContent.startsWith('finished')")
    st = status(station)
    miss, t_ca = st["miss_m"], st["intercept_time_s"]
    assert page.text_content("#sim-msg") == (  # the one rounding rule (numbers.py)
        f"finished: {st['outcome']}, miss {fmt_num(miss)} m at t = {fmt_num(t_ca)} s"
    )
    assert page.text_content("#st-rate") == "loop — Hz"


# ---------------------------------------------------------------------- B10: plots
def test_timeline_zoom_and_recorded_fields(station, page):
    s = station.session
    s.set_gains(s.default_gains())
    s.start(SortieConfig(load_scenario("cv-top-to-bottom"), speed="5"))
    while s.sim.time_s < 1.0:
        time.sleep(0.02)
    s.set_gains(s.gains.replace(k_p=0.05))
    while s.state != "finished":
        time.sleep(0.05)
    name = s.recording["file"]
    s.set_gains(s.default_gains())
    goto(page, station)
    # live: the gain edit and the closest approach are markers on the shared timeline
    page.wait_for_selector("#timeline .k-gain")
    assert page.text_content("#timeline .k-gain") == "k_p 0.03 → 0.05"
    assert "closest approach" in page.text_content("#timeline .k-closest")
    assert "k_p 0.03 → 0.05" in page.text_content("#gain-edits")

    # zoom one plot: every time plot follows
    box = page.locator(".plot").first.locator(".u-over").bounding_box()
    whole = page.evaluate(
        "(u => u.scales.x.max - u.scales.x.min)(window.peregrine.plots.find(u => !u.xy))"
    )  # the whole sortie, recovery after the pass included
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.wheel(0, -300)
    # the wheel zooms in the page's event handler (later on a loaded machine): wait for it
    page.wait_for_function(
        "window.peregrine.plots.some(u => !u.xy && u.scales.x.max - u.scales.x.min < "
        f"{0.9 * whole})"
    )
    ranges = page.evaluate("window.peregrine.plots.filter(u => !u.xy)"
                           ".map(u => [u.scales.x.min, u.scales.x.max])")  # fmt: skip
    assert all(r == ranges[0] for r in ranges) and ranges[0][1] - ranges[0][0] < 0.9 * whole
    page.dblclick(".plot .u-over")
    page.wait_for_function("window.peregrine.plots[0].scales.x.min === 0")
    # a legend entry toggles its series
    page.click(".plot:nth-child(2) .u-legend .u-series:nth-child(3)")
    assert page.evaluate("window.peregrine.plots[1].series[2].show") is False

    # replay: any recorded numeric field can be added as a plot; the XY plot has the track
    # (where the button is on the page, each frame until it is pressed: the plots' legends
    # once grew a line when their values came, moving the button between a press and its
    # release, and the click was lost)
    page.evaluate(
        """(() => {
        const b = document.getElementById('btn-add-plot'), tops = (window.addPlotTops = []);
        let pressed = false;
        window.addEventListener('pointerdown', () => { pressed = true; }, true);
        const look = () => {
          if (pressed) return;
          if (!b.parentElement.hidden) {
            const top = Math.round(b.getBoundingClientRect().top + window.scrollY);
            if (tops[tops.length - 1] !== top) tops.push(top);
          }
          requestAnimationFrame(look);
        };
        look();
      })()"""
    )
    api(station, "POST", "/api/replay/open", {"name": name})
    page.wait_for_selector("#add-plot-row:not([hidden])", timeout=10000)
    page.wait_for_function("window.peregrine.plotView.dirty === false")  # its values drawn
    page.select_option("#add-field", "thrust_cmd")
    page.click("#btn-add-plot")
    tops = page.evaluate("window.addPlotTops")
    assert len(tops) == 1, f"the Add plot button moved while the plots filled in: {tops}"
    page.wait_for_function(
        "window.peregrine.plots.some(u => u.def && u.def.title === 'thrust_cmd')"
    )
    thrust = page.evaluate(
        "window.peregrine.plots.find(u => u.def && u.def.title === 'thrust_cmd').data[1]"
    )
    series = api(station, "GET", f"/api/logs/{name}/series")
    assert thrust == series["fields"]["thrust_cmd"]
    assert min(thrust) > 0.0 and max(thrust) <= 1.0
    xy = page.evaluate("window.peregrine.plots.find(u => u.xy).data[1]")
    assert len(xy[0]) > 50 and len(xy[0]) == len(xy[1])
    assert page.text_content("#timeline .k-gain") == "k_p 0.03 → 0.05"  # from the recording


def test_timeline_labels_of_events_close_together_do_not_overlap(station, page):
    s = station.session
    s.set_gains(s.default_gains())
    # ideal perception: no track-loss events crowding the rows, only the edits under test
    s.start(SortieConfig(load_as_written("cv-top-to-bottom"), speed="5"))
    for k_p in (0.04, 0.05, 0.06):  # three edits a few ticks apart: a few pixels on the page
        t = max(s.sim.time_s, 1.0)
        while s.sim.time_s < t + 0.05:
            time.sleep(0.005)
        s.set_gains(s.gains.replace(k_p=k_p))
    while s.state != "finished":
        time.sleep(0.05)
    goto(page, station)  # (gains put back after: an edit now would be a mark at the end)
    page.wait_for_function("document.querySelectorAll('#timeline .k-gain').length === 3")
    marks = page.evaluate(
        """[...document.querySelectorAll('#timeline .mark')].map(m => {
             const r = m.getBoundingClientRect();
             return {left: r.left, right: r.right, top: r.top, text: m.textContent, title: m.title,
                     whole: m.scrollWidth <= m.clientWidth, bare: m.classList.contains('bare')};
           }).sort((a, b) => a.left - b.left)"""
    )
    gains = [m for m in marks if "k_p" in m["text"]]
    assert [m["text"] for m in gains] == ["k_p 0.03 → 0.04", "k_p 0.04 → 0.05", "k_p 0.05 → 0.06"]
    assert gains[1]["left"] - gains[0]["left"] < 30  # close enough to have overlapped
    for a, b in itertools.combinations(marks, 2):  # no label runs into another on its row
        if a["top"] == b["top"] and not (a["bare"] and b["bare"]):  # (ticks: text on hover)
            assert a["right"] <= b["left"] + 0.01 or b["right"] <= a["left"] + 0.01, (a, b)
    assert all(m["whole"] and not m["bare"] for m in gains)  # each on a row with room
    assert all(m["title"].endswith(m["text"]) for m in marks)  # every text whole on hover
    s.set_gains(s.default_gains())


# ---------------------------------------------------------------------- B11: gains panel
def test_gains_panel_refusal_reverts_and_gain_sets_round_trip(station, page, tmp_path):
    station.session.reset()
    station.session.set_gains(station.session.default_gains())
    goto(page, station)
    page.fill('#gains input[data-gain="K_y"]', "70")
    page.click("#btn-apply-gains")
    page.wait_for_selector("#gains-msg.err")
    assert page.text_content("#gains-msg") == "K_y refused: 70 is outside 0 to 10; it stays 3."
    assert page.input_value('#gains input[data-gain="K_y"]') == "3"  # back to the value in force
    assert station.session.gains.K_y == 3.0

    page.fill("#gainset-name", "")
    page.click("#btn-save-gainset")
    assert page.text_content("#gains-msg") == "give the gain set a name first."

    # a non-default value is highlighted and has its own reset
    page.fill('#gains input[data-gain="k_d"]', "0.02")
    page.click("#btn-apply-gains")
    page.wait_for_selector('#gains tr[data-gain="k_d"].nondefault')
    assert "rad/px" in page.text_content('#gains tr[data-gain="k_d"]')
    assert "FOV-holding" in page.text_content('#gains tr[data-gain="k_d"] td.meaning')
    page.fill("#gainset-name", "soft-yaw")
    page.click("#btn-save-gainset")
    page.wait_for_function(
        "document.querySelector('#gains-msg').textContent === \"saved 'soft-yaw'\""
    )
    page.click('#gains tr[data-gain="k_d"] button[data-reset]')
    page.wait_for_function("!document.querySelector('#gains tr[data-gain=\"k_d\"]')"
                           ".classList.contains('nondefault')")  # fmt: skip
    assert station.session.gains.k_d == 0.01

    # download the set, upload it under another name, load it: it flies
    with page.expect_download() as dl:
        page.click("#gainset-download")
    text = Path(dl.value.path()).read_text()
    assert "k_d = 0.02" in text
    f = tmp_path / "uploaded.toml"
    f.write_text(text)
    page.fill("#gainset-name", "")
    page.set_input_files("#gainset-upload", str(f))
    page.wait_for_function("document.querySelector('#gains-msg').textContent.startsWith("
                           "\"uploaded 'uploaded'\")")  # fmt: skip
    page.select_option("#gainsets", "uploaded")
    page.click("#btn-load-gainset")
    page.wait_for_function("document.querySelector('#st-gains').textContent"
                           " === 'gains: gain set uploaded'")  # fmt: skip
    assert station.session.gains.k_d == 0.02

    # the search box narrows the table
    page.fill("#gain-search", "yaw-rate")
    visible = page.evaluate("[...document.querySelectorAll('#gains tr[data-gain]')]"
                            ".filter(r => !r.hidden).map(r => r.dataset.gain)")  # fmt: skip
    assert visible == ["k_p", "k_d"]
    station.session.set_gains(load_scenario("cv-top-to-bottom").gains_obj(), "defaults")


# ---------------------------------------------------------------------- B13: image plane
def test_image_plane_markers_leave_the_balloon_visible_and_an_outside_estimate_is_an_arrow(
    station, page
):
    station.session.reset()
    goto(page, station)
    snap = {"t": 1.0, "range_m": 3.0, "target": {"diameter_m": 0.3},
            "image": {"w": 640, "h": 480, "f": 320, "vfov_deg": 73.7},
            "e_raw_px": [40, 20], "e_est_px": [40, 20], "k_a": 2}  # fmt: skip
    px = page.evaluate(  # in one go: a telemetry redraw could come between two calls
        "(s) => { drawImagePlane(s); const at = (x, y) => [...img.ctx.getImageData(x, y, 1, 1)"
        ".data].slice(0, 3);"
        " return [at(360, 260), at(360 + 22, 260), window.peregrine.edgeArrow]; }",
        snap,
    )
    # the balloon (32 px across at 3 m) is not painted over: no marker colour at its centre
    assert px[0] not in ([25, 193, 91], [255, 159, 28])
    assert px[1][1] > 150 and px[1][0] < 80  # the estimate's circle runs outside its edge
    assert px[2] is None
    snap["e_est_px"] = [0, -400]  # 160 px above the top edge
    arrow = page.evaluate("(s) => { drawImagePlane(s); return window.peregrine.edgeArrow; }", snap)
    assert arrow["x"] == pytest.approx(320, abs=1) and arrow["y"] == pytest.approx(18, abs=1)


# ---------------------------------------------------------------------- B14: campaign folders
def test_campaign_recordings_in_a_subfolder_are_browsed_and_opened(station, page):
    name = fly(station, scenario="static-ahead-20m")
    sub = station.log_dir / "static-n1"  # what `campaign --log logs/static-n1` leaves
    sub.mkdir(exist_ok=True)
    shutil.copy(station.log_dir / name, sub / "campaign-sortie.mcap")
    page.goto(station.url())
    page.goto(base(station) + "sorties")
    page.wait_for_selector("#folder option[value='static-n1']", state="attached")
    page.select_option("#folder", "static-n1")
    row = page.locator('#logs tbody tr[data-name="static-n1/campaign-sortie.mcap"]')
    row.wait_for()
    assert page.text_content("#folder-shown") == "(logs/static-n1/)"
    assert page.text_content("#count") == "1 of 1 sorties"
    assert "static-ahead-20m" in row.text_content() and "HIT" in row.text_content()
    assert "folder=static-n1" in page.url  # a reload stays in the folder
    row.locator("button[data-act=open]").click()
    page.wait_for_url(re.compile(r"/(\?.*)?$"))
    page.wait_for_function(
        "window.peregrine.snap && window.peregrine.snap.status.replay"
        " && window.peregrine.snap.status.replay.file === 'static-n1/campaign-sortie.mcap'"
    )
    # the plots show the whole recorded sortie, read from the subfolder
    page.wait_for_function("window.peregrine.plots.length >= 5 && "
                           "window.peregrine.plots[0].data[0].length > 50")  # fmt: skip
    assert "static-n1/campaign-sortie.mcap" in page.text_content("#rp-file")


# ---------------------------------------------------------------------- B12: 3D view per viewer
def _cameras(station) -> dict:
    return {
        cid: (np.array(c.camera.position), np.array(c.camera.look_at))
        for cid, c in station.viser.get_clients().items()
    }


def test_3d_view_presets_are_per_viewer(station, browser):
    fly(station, scenario="static-ahead-20m")  # a sortie on screen: the engagement is known
    pages = [browser.new_page(viewport={"width": 1500, "height": 1000}) for _ in range(2)]
    try:
        for pg in pages:
            pg.goto(station.url())
            view = pg.frame_locator("#viser").get_by_label("View", exact=True)
            view.wait_for(timeout=60000)  # each viewer's own View control, from the server
            assert view.input_value() == "fit engagement"
        deadline = time.monotonic() + 20
        while len(_cameras(station)) < 2:
            assert time.monotonic() < deadline, "the viewers did not connect"
            time.sleep(0.1)
        # a viewer's camera settles on its first fit after it connects (later on a loaded
        # machine): take "before" once no camera has moved for half a second
        before = _cameras(station)
        while True:
            time.sleep(0.5)
            now = _cameras(station)
            if now.keys() == before.keys() and all(
                np.allclose(now[c][0], before[c][0]) for c in now
            ):
                break
            assert time.monotonic() < deadline, "the viewers' cameras did not settle"
            before = now
        # viewer A picks "top" in its own View control
        frame = pages[0].frame_locator("#viser")
        frame.get_by_label("View", exact=True).click()
        frame.get_by_role("option", name="top", exact=True).click()
        deadline = time.monotonic() + 20
        moved: list = []
        while not moved:
            assert time.monotonic() < deadline, "no viewer's camera moved"
            now = _cameras(station)
            moved = [c for c in now if c in before and not np.allclose(now[c][0], before[c][0])]
            time.sleep(0.1)
        assert len(moved) == 1  # one viewer's camera, not every viewer's
        pos, look = _cameras(station)[moved[0]]
        above = pos - look
        assert above[2] > 10.0 and np.hypot(above[0], above[1]) < 0.05 * above[2]  # top-down
        other = next(c for c in before if c != moved[0])
        assert np.allclose(_cameras(station)[other][0], before[other][0])  # B kept its view
        # each page's control says what its viewer shows
        assert frame.get_by_label("View", exact=True).input_value() == "top"
        other_view = pages[1].frame_locator("#viser").get_by_label("View", exact=True)
        assert other_view.input_value() == "fit engagement"
        pages[0].locator("#viser").screenshot(path=str(station.log_dir.parent / "top-view.png"))
    finally:
        for pg in pages:
            pg.close()


# ------------------------------------------------------------------------ gain studies
def test_gain_studies_are_listed_and_a_trial_flies_beside_the_defaults(station, page):
    from .test_studies_api import make_study

    make_study(station.data_dir, "page-study")
    station.session.reset()
    goto(page, station)
    page.click("#btn-studies-refresh")
    page.wait_for_function("window.peregrine.study && window.peregrine.study.name === 'page-study'")
    rows = page.locator("#trials tbody tr")
    assert rows.count() == 5
    # sorted by loss, the best first and marked; the failed trial last, without a Fly button
    top = rows.nth(0)
    assert top.get_attribute("data-trial") == "2" and "best" in top.get_attribute("class")
    assert "k_v 6, K_y 4.5" in rows.nth(0).text_content()
    assert rows.nth(4).locator("button").count() == 0
    assert "4 of 5 trials done · best #2" in page.text_content("#study-info")
    best = page.evaluate("window.peregrine.studyPlot()")
    assert best == pytest.approx([0.40, 0.40, 0.10, 0.10, 0.10])
    page.select_option("#speed", "max")
    rows.nth(0).locator("button[data-act=fly]").click()
    page.wait_for_function("document.getElementById('study-msg').textContent.includes('flying at')")
    st = status(station)
    assert st["gains_source"] == "study page-study trial #2"
    assert st["compare"]["scenario"] == "static-ahead-20m"
    # what the operator sees: the gains in force are the trial's, the legend names both sorties
    page.wait_for_function(
        "document.getElementById('gains-source').textContent.includes('trial #2')"
    )
    page.wait_for_function(  # the panel reloads the gains in force (the defaults' 1.8 before)
        "parseFloat(document.querySelector('#gains input[data-gain=\"k_v\"]').value) === 6"
    )
    assert float(page.input_value('#gains input[data-gain="K_y"]')) == 4.5
    legend = "document.querySelector('#plots').textContent.includes('· B')"
    page.wait_for_function(f"window.peregrine.plots.length >= 5 && {legend}")


def test_the_header_labels_ideal_sensors(station, page):
    from groundstation.sim.profiles import with_profile

    s = station.session
    s.start(SortieConfig(with_profile(load_scenario("sm-tailgate"), "ideal"), "png", 0,
                         "projected", "1"))  # fmt: skip
    goto(page, station)
    page.wait_for_function(
        "document.querySelector('#st-scenario').textContent.includes('IDEAL SENSORS')"
    )
    s.reset()
    s.start(SortieConfig(load_scenario("sm-tailgate"), "png", 0, "projected", "1"))
    page.wait_for_function(
        "document.querySelector('#st-scenario').textContent.includes('outdoor-gnss')"
    )
    assert "IDEAL" not in page.text_content("#st-scenario")
    s.reset()
