"""The operator's loop in a real browser: the page never lies about the gains flying (a re-fly
or a trial flies its gains for that sortie only, a typed value is applied by Start, Apply names
every refusal), errors read as errors, the controls agree with the header after a reload, no
stale text, one rounding rule, and the views (3D fit, image plane, gains panel, timeline)
show the whole of what they show. Rules: docs/operator-gains.md."""

import json
import shutil
import time

import numpy as np

from groundstation.app.numbers import fmt_num
from groundstation.app.session import SortieConfig
from groundstation.recording.reader import inspect_log
from groundstation.scenario import load_scenario

from . import test_dashboard
from .as_written import load_as_written
from .browser_support import needs_chromium
from .test_dashboard import api, base, fly, goto, status

pytestmark = needs_chromium
page = test_dashboard.page  # the fixture: a page whose script errors fail the test


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


# ---------------------------------------------------------------------- 1: re-fly gains
def test_refly_gains_fly_that_sortie_only_and_the_next_start_flies_the_operators(station, page):
    clean(station)
    api(station, "PUT", "/api/gains", {"K_y": 4})  # the operator's edit
    name = fly(station)
    assert station.session.sim.loop.gains.K_y == 4.0
    goto(page, station)
    api(
        station,
        "POST",
        f"/api/logs/{name}/refly",
        {"speed": "max", "gains": {"K_y": 2, "a_max": 8}},
    )
    page.wait_for_function(
        "document.querySelector('#st-gains').textContent.startsWith('gains: re-fly of')"
    )
    assert station.session.sim.loop.gains.K_y == 2.0
    wait_state(station, "finished")
    # a plain Start flies the operator's gains again, and the header says which
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "max")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap.status.gains_source === 'defaults'")
    wait_state(station, "finished")
    rec = station.session.recording["file"]
    flown = recorded_gains(station, rec)
    assert flown["K_y"] == 4.0 and flown["a_max"] == 5.0  # main: K_y 2, a_max 8
    page.wait_for_function(
        "document.querySelector('#st-gains').textContent === 'gains: defaults + edits K_y* 3→4'"
    )
    # cv-top-to-bottom has no [gains]: the panel never says it carries its own
    assert page.is_hidden("#gains-note")
    clean(station)


# ---------------------------------------------------------------------- 2: typed, not applied
def test_a_typed_gain_is_applied_by_start_and_a_bad_one_refuses_the_start(station, page):
    clean(station)
    goto(page, station)
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "max")
    page.fill('#gains input[data-gain="K_z"]', "4")  # typed, Apply not pressed
    page.click("#btn-start")
    page.wait_for_function("document.querySelector('#sim-msg').textContent.startsWith('started')")
    assert station.session.sim.loop.gains.K_z == 4.0  # main: 3, the typed value discarded
    assert page.text_content("#sim-msg") == "started, with your typed value applied: K_z = 4"
    wait_state(station, "finished")
    assert recorded_gains(station, station.session.recording["file"])["K_z"] == 4.0
    epoch = status(station)["epoch"]
    page.fill('#gains input[data-gain="K_y"]', "-1")
    page.fill('#gains input[data-gain="k_p"]', "0.05")
    page.click("#btn-start")
    page.wait_for_selector("#sim-msg.err")
    text = page.text_content("#sim-msg")
    assert text.startswith("not started: a typed gain is refused (fix or clear it):")
    assert "K_y refused: -1 is outside 0 to 10" in text
    assert status(station)["epoch"] == epoch  # nothing started, nothing applied
    assert station.session.gains.k_p == 0.03
    clean(station)


# ---------------------------------------------------------------------- 3: Apply, upload
def test_apply_applies_the_valid_edits_and_names_every_refused_one(station, page, tmp_path):
    clean(station)
    goto(page, station)
    page.fill('#gains input[data-gain="K_y"]', "-1")
    page.fill('#gains input[data-gain="K_z"]', "4")
    page.fill('#gains input[data-gain="k_p"]', "abc")
    page.click("#btn-apply-gains")
    page.wait_for_function("document.querySelector('#gains-msg').textContent.includes('K_z')")
    assert page.text_content("#gains-msg") == (
        "applied: K_z = 4. K_y refused: -1 is outside 0 to 10; it stays 3. "
        'k_p refused: "abc" is not a number; it stays 0.03 rad/s/px.'
    )
    assert station.session.gains.K_z == 4.0 and station.session.gains.K_y == 3.0
    assert page.input_value('#gains input[data-gain="K_y"]') == "3"
    assert "bad" in page.get_attribute('#gains input[data-gain="K_y"]', "class")
    assert "bad" in page.get_attribute('#gains input[data-gain="k_p"]', "class")

    # a bad gain set file: an error naming all its problems, nothing saved
    f = tmp_path / "broken.toml"
    f.write_text("K_y = -1\nfoo = 2\nk_p = 0.05\nK_z = 'x'\n")
    page.fill("#gainset-name", "")
    page.set_input_files("#gainset-upload", str(f))
    page.wait_for_selector("#gains-msg.err")
    text = page.text_content("#gains-msg")
    assert text.startswith("gain set file 'broken' refused, nothing saved: 3 problems:")
    assert "K_y" in text and "foo" in text and "K_z" in text and "uploaded" not in text
    assert "broken" not in api(station, "GET", "/api/gainsets")
    clean(station)


# ---------------------------------------------------------------------- 4: log folder gone
def test_start_with_an_unusable_log_folder_shows_the_recording_banner(station, page):
    clean(station)
    goto(page, station)
    logs = station.log_dir
    logs.mkdir(exist_ok=True)
    aside = logs.with_name("logs-aside")
    logs.rename(aside)
    logs.write_text("not a folder")  # the log folder became unusable
    try:
        page.select_option("#scenario", "cv-top-to-bottom")
        page.select_option("#speed", "max")
        page.click("#btn-start")
        page.wait_for_selector("#rec-banner.err", timeout=10000)
        banner = page.text_content("#rec-banner")
        assert banner.startswith("Recording failed: cannot create a log file in")
        assert "no longer recorded" in banner or "not recorded" in banner
        assert "Internal Server Error" not in page.text_content("#sim-msg")
        assert page.text_content("#sim-msg").startswith("started")
        wait_state(station, "finished")
    finally:
        station.session.reset()
        logs.unlink()
        aside.rename(logs)
    clean(station)


# ---------------------------------------------------------------------- 5: reload, compare
def test_after_reset_and_reload_the_header_and_the_controls_agree_and_start_flies_them(
    station, page
):
    clean(station)
    station.session.start(SortieConfig(load_scenario("static-ahead-20m"), "pg", 2, speed="max"))
    wait_state(station, "finished")
    station.session.reset()
    goto(page, station)
    header = page.text_content("#st-scenario")
    assert header.startswith("static-ahead-20m · pg · seed 2")
    assert page.input_value("#scenario") == "static-ahead-20m"  # main: cv-top-to-bottom
    assert page.input_value("#law") == "pg" and page.input_value("#seed") == "2"
    page.select_option("#speed", "max")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap.status.state !== 'idle'")
    cfg = station.session.config
    assert (cfg.scenario.name, cfg.law, cfg.seed) == ("static-ahead-20m", "pg", 2)
    wait_state(station, "finished")
    clean(station)


def test_compare_from_an_idle_page_and_the_finished_line_after_a_reload(station, page):
    clean(station)
    a = fly(station)
    st = status(station)
    goto(page, station)  # a finished sortie, the page loaded after: the line is there
    expected = (
        f"finished: {st['outcome']}, miss {fmt_num(st['miss_m'])} m"
        f" at t = {fmt_num(st['intercept_time_s'])} s"
    )
    page.wait_for_function(f"document.querySelector('#sim-msg').textContent === {expected!r}")
    station.session.reset()
    goto(page, station, f"&compare={a}")
    page.wait_for_function(
        f"document.querySelector('#cmp-legend').textContent.includes({a!r})", timeout=10000
    )
    assert status(station)["compare"]["file"] == a  # main: "open a sortie ... before comparing"
    assert "compare with" not in page.text_content("#sim-msg")
    b_points = page.evaluate("window.peregrine.plots[3].data.length")
    assert b_points == 3  # the compared sortie's curve is drawn
    clean(station)


# ---------------------------------------------------------------------- 6: stale text, rounding
def test_no_stale_text_after_reset_and_one_rounding_rule(station, page):
    clean(station)
    goto(page, station)
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "1")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap.t > 0.5", timeout=15000)
    page.fill('#gains input[data-gain="k_p"]', "0.05")
    page.click("#btn-apply-gains")
    page.wait_for_function(
        "document.querySelector('#gains-applied').textContent.includes('applied at t =')"
    )
    assert page.is_visible("#rec-banner")
    page.click("#btn-reset")
    page.wait_for_function("window.peregrine.snap.status.state === 'idle'")
    page.wait_for_function("document.querySelector('#rec-banner').hidden")
    page.wait_for_function("document.querySelector('#gains-applied').textContent === ''")

    # one rounding rule: the miss reads the same in the header, the message line, the
    # timeline and the sorties page
    name = fly(station)
    miss = status(station)["miss_m"]
    shown = fmt_num(miss)
    assert len(shown.replace("0.", "").lstrip("0")) <= 4
    goto(page, station)
    page.wait_for_function("document.querySelector('#st-outcome').textContent.includes('miss')")
    assert f"miss {shown} m" in page.text_content("#st-outcome")
    assert f"miss {shown} m" in page.text_content("#sim-msg")
    assert f"miss {shown} m" in page.text_content("#timeline .k-closest")
    page.goto(base(station) + "sorties")
    row = page.locator(f'#logs tbody tr[data-name="{name}"]')
    row.wait_for()
    assert row.locator("td").nth(6).text_content() == shown
    clean(station)


def test_a_trial_message_does_not_outlive_its_sortie(station, page):
    from .test_studies_api import make_study

    make_study(station.data_dir, "stale-study")
    clean(station)
    goto(page, station)
    page.click("#btn-studies-refresh")
    page.wait_for_function("window.peregrine.study && window.peregrine.study.name")
    page.select_option("#study", "stale-study")
    page.wait_for_function("window.peregrine.study.name === 'stale-study'")
    page.select_option("#speed", "max")
    page.locator("#trials tbody tr").nth(0).locator("button[data-act=fly]").click()
    page.wait_for_function("window.peregrine.snap.status.gains_source.includes('trial #2')")
    wait_state(station, "finished")
    page.wait_for_function("window.peregrine.snap.status.state === 'finished'")
    page.wait_for_function(
        "!document.getElementById('study-msg').textContent.includes('flying')", timeout=5000
    )
    assert page.text_content("#study-msg").startswith("trial #2 flown: ")
    # study history: whole trial numbers on its axis
    ticks = page.evaluate("window.peregrine.studyTicks")
    assert len(ticks) >= 2 and all(float(t).is_integer() for t in ticks), ticks
    # the trial's gains were that sortie's only: a plain Start flies the defaults
    page.select_option("#scenario", "cv-top-to-bottom")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap.status.gains_source === 'defaults'")
    assert station.session.sim.loop.gains.k_v == 1.8
    clean(station)


# ---------------------------------------------------------------------- 7: re-fly form, legend
def test_refly_form_offers_the_recorded_gains_and_the_legend_shows_only_what_differs(station, page):
    clean(station)
    api(station, "PUT", "/api/gains", {"K_y": 2.123456789})
    name = fly(station)
    clean(station)
    page.goto(station.url())
    page.goto(base(station) + "sorties")
    row = page.locator(f'#logs tbody tr[data-name="{name}"]')
    row.locator("button[data-act=refly]").click()
    form = page.locator("#refly-form")
    form.wait_for()
    assert form.locator('input[data-gain="K_y"]').input_value() == "2.123456789"  # prefilled
    assert form.locator('input[data-gain="k_p"]').input_value() == "0.03"
    form.locator('input[data-gain="a_max"]').fill("8")
    page.select_option("#refly-speed", "max")
    form.locator("button#refly-go").click()
    page.wait_for_url("**compare=**")
    wait_state(station, "finished")
    g = station.session.sim.loop.gains
    assert (g.K_y, g.a_max) == (2.123456789, 8.0)
    page.wait_for_function("document.querySelector('#cmp-legend').textContent.includes('B')")
    page.wait_for_function(
        "document.querySelector('#cmp-legend').textContent.includes('a_max')", timeout=10000
    )
    legend = page.text_content("#cmp-legend")
    assert "a_max 8 (A)" in legend or "a_max 8" in legend
    assert "a_max 5" in legend  # B's own value beside
    assert "K_y" not in legend and "k_dob" not in legend  # the same in both: not listed
    assert "2.123456789" not in legend
    # replay: the header names the replayed sortie's gains, not the session's
    reflown = station.session.recording["file"]
    api(station, "PUT", "/api/gains", {"K_z": 4})
    api(station, "POST", "/api/replay/open", {"name": reflown})
    goto(page, station)
    page.wait_for_function(
        "document.querySelector('#st-gains').textContent.startsWith('gains: recorded in')"
    )
    head = page.text_content("#st-gains")
    assert "K_y 2.123" in head and "a_max 8" in head and "K_z" not in head
    clean(station)


# ---------------------------------------------------------------------- 9: gains panel, plots
def test_gains_panel_groups_search_and_timeline_labels(station, page):
    from onboard.gains import GAIN_GROUPS, GAIN_SPECS

    clean(station)
    goto(page, station)
    groups = page.evaluate(
        "[...document.querySelectorAll('#gains tr.group')].map(r => [r.textContent,"
        " (() => { let n = 0, e = r.nextElementSibling;"
        " while (e && e.dataset.gain) { n++; e = e.nextElementSibling; } return n; })()])"
    )
    assert [g for g, _ in groups] == list(GAIN_GROUPS)  # from onboard/gains.py
    assert "other" not in [g.lower() for g, _ in groups]
    assert max(n for _, n in groups) <= 9 and sum(n for _, n in groups) == len(GAIN_SPECS)
    page.fill("#gain-search", "zzz-nothing")
    page.wait_for_selector("#gains-none:not([hidden])")
    assert page.text_content("#gains-none") == 'no gain matches "zzz-nothing"'
    page.fill("#gain-search", "")
    assert page.is_hidden("#gains-none")

    # timeline labels are whole: those close together go on rows of their own (ideal
    # perception: no track-loss events crowding the rows, only the edits under test)
    s = station.session
    s.start(SortieConfig(load_as_written("cv-top-to-bottom"), speed="5"))
    for k_p in (0.04, 0.05):
        t = max(s.sim.time_s, 1.0)
        while s.sim.time_s < t + 0.05:
            time.sleep(0.005)
        s.set_gains(s.gains.replace(k_p=k_p))
    wait_state(station, "finished")
    goto(page, station)
    page.wait_for_function("document.querySelectorAll('#timeline .k-gain').length === 2")
    marks = page.evaluate(
        """[...document.querySelectorAll('#timeline .mark')].map(m => {
             const r = m.getBoundingClientRect();
             return {left: r.left, right: r.right, top: r.top, text: m.textContent,
                     whole: m.scrollWidth <= m.clientWidth + 1,
                     bare: m.classList.contains('bare')};
           })"""
    )
    # every label whole ("k_p 0.0…", "waiti…" were cut); a tick with no room on the label
    # rows sits on a row of its own, its text on hover
    assert all(m["whole"] or m["bare"] for m in marks), marks
    assert all(m["whole"] for m in marks if "k_p" in m["text"]), marks
    for a in marks:
        for b in marks:
            if a is not b and a["top"] == b["top"] and not (a["bare"] and b["bare"]):
                assert a["right"] <= b["left"] + 0.5 or b["right"] <= a["left"] + 0.5, (a, b)
    clean(station)


# ---------------------------------------------------------------------- D: every field
def test_every_recorded_numeric_field_can_be_plotted_dkf_included(station, page):
    clean(station)
    name = fly(station)
    series = api(station, "GET", f"/api/logs/{name}/series")
    dkf = [k for k in series["fields"] if k.startswith("dkf.")]
    assert "dkf.state.1" in dkf and "dkf.cov_diag.0" in dkf
    assert len(series["fields"]["dkf.state.1"]) == len(series["t_s"])
    api(station, "POST", "/api/replay/open", {"name": name})
    goto(page, station)
    page.wait_for_selector("#add-plot-row:not([hidden])")
    options = page.evaluate("[...document.querySelectorAll('#add-field option')].map(o => o.value)")
    assert "dkf.state.1" in options and "accel_normal_m_s2" in options
    page.select_option("#add-field", "dkf.state.1")
    page.click("#btn-add-plot")
    page.wait_for_function(
        "window.peregrine.plots.some(u => u.def && u.def.title === 'dkf.state.1')"
    )
    data = page.evaluate(
        "window.peregrine.plots.find(u => u.def && u.def.title === 'dkf.state.1').data[1]"
    )
    assert data == series["fields"]["dkf.state.1"]
    # the legend's value follows the one rounding rule
    v = page.text_content(".plot:nth-child(2) .u-legend .u-series:nth-child(2) .u-value")
    assert v == "—" or len(v.replace("-", "").replace(".", "").lstrip("0")) <= 4
    shutil.rmtree(station.log_dir / "nothing", ignore_errors=True)
    clean(station)


# ---------------------------------------------------------------------- 8: 3D view, image plane
def _project(points, cam):
    """Points (N x 3) in the view of a viser camera: x, y in [-1, 1] inside, depth."""
    pos, look = np.array(cam.position), np.array(cam.look_at)
    f = (look - pos) / np.linalg.norm(look - pos)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    v = np.asarray(points, dtype=float) - pos
    z = v @ f
    tan_v = np.tan(cam.fov / 2.0)
    return (v @ r) / (z * tan_v * cam.aspect), (v @ u) / (z * tan_v), z


def test_3d_fit_frames_both_trajectories_with_labels_and_panels_clear(station, browser):
    clean(station)
    fly(station)
    s = station.session
    vehicle, target = np.array(s._trail_vehicle), np.array(s._trail_target)
    pg = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        pg.goto(station.url())
        pg.frame_locator("#viser").get_by_label("View", exact=True).wait_for(timeout=60000)
        deadline = time.monotonic() + 45  # software WebGL on a busy machine
        while True:  # the viewer's camera, once it has reported its view and been fitted
            cams = list(station.viser.get_clients().values())
            if cams and not np.allclose(cams[-1].camera.position, (-11.0, 1.0, 12.0)):
                break
            assert time.monotonic() < deadline, "the view was never fitted"
            time.sleep(0.1)
        cam = cams[-1].camera
        x, y, z = _project(np.concatenate([vehicle, target]), cam)
        assert (z > 0).all() and (np.abs(x) <= 1).all() and (np.abs(y) <= 1).all()
        extent = max((x.max() - x.min()) / 2, (y.max() - y.min()) / 2)
        assert extent >= 0.5, extent  # main: the engagement small in a corner
        # the outcome label is not on the vehicle (which ends at the closest point)
        label = next(h for h in station.scene._handles if h.name == "/closest_label")
        w_px, h_px = pg.evaluate("[document.getElementById('viser').clientWidth,"
                                 " document.getElementById('viser').clientHeight]")  # fmt: skip
        lx, ly, _ = _project([label.position], cam)
        vx, vy, _ = _project([vehicle[-1]], cam)
        apart_px = np.hypot((lx - vx) * cam.aspect, ly - vy)[0] * h_px / 2
        assert apart_px > 0.1 * h_px, apart_px
        # the interceptor's label (0.8 m above it) at the start is inside the view, its text
        # (about 70 px) too
        ix, iy, _ = _project([vehicle[0] + [0, 0, 0.8]], cam)
        assert 40 < (ix[0] + 1) / 2 * w_px < w_px - 40 and abs(iy[0]) < 0.95
        frame = next(f for f in pg.frames if "/viser" in f.url)
        rects = frame.evaluate(
            """() => {
              const box = (e) => { const r = e.getBoundingClientRect(); return [r.top, r.bottom]; };
              const panel = [...document.querySelectorAll('.mantine-Paper-root')]
                .find(e => getComputedStyle(e).position === 'fixed'
                           && e.textContent.includes('View'));
              const notes = [...document.querySelectorAll('.mantine-Notification-root')]
                .filter(e => getComputedStyle(e).visibility !== 'hidden');
              return {h: innerHeight, panel: box(panel), notes: notes.map(box)};
            }"""
        )
        assert rects["panel"][1] <= 0.3 * rects["h"], rects  # main: a sheet at the bottom
        for _top, bottom in rects["notes"]:
            assert bottom <= 0.3 * rects["h"], rects
        pg.locator("#viser").screenshot(path=str(station.log_dir.parent / "fit-1280.png"))
    finally:
        pg.close()
    clean(station)


def test_image_plane_band_end_marker_and_recent_track_in_replay(station, page):
    clean(station)
    goto(page, station)
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "5")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap.status.state === 'finished'", timeout=60000)
    page.wait_for_function(  # the estimate, or after the recovery the last one, is marked
        "window.peregrine.band !== null"
        " && (window.peregrine.estMarker !== null || window.peregrine.endMarker !== null)"
    )
    band = page.evaluate("window.peregrine.band")
    own = page.evaluate(
        "[window.peregrine.plotView.own.t_s, window.peregrine.plotView.own.columns]"
    )
    t, ey = own[0], own[1]["e_y_px"]
    seen = [(tt, v) for tt, v in zip(t, ey, strict=True) if v is not None]
    t_pass = station.session.status()["intercept_time_s"]  # after it, the recovery flies on
    settled = [v for tt, v in seen if seen[0][0] + 1.0 <= tt <= t_pass]
    inside = sum(abs(v - band["centre"]) <= band["half"] for v in settled) / len(settled)
    assert inside >= 0.9, (band, inside)  # main: centred on the first, transient estimate
    marker = page.evaluate("window.peregrine.estMarker")
    if marker is not None:
        assert marker["r"] <= 40 and 0 <= marker["x"] <= 640 and 0 <= marker["y"] <= 480
    else:  # where the sortie's last estimate put the target
        end = page.evaluate("window.peregrine.endMarker")
        assert all(v is not None for v in (end["x"], end["y"])), end
    # replay: a seek shows the track of the second and a half before the cursor
    name = station.session.recording["file"]
    api(station, "POST", "/api/replay/open", {"name": name})
    api(station, "POST", "/api/replay/seek", {"t_s": 3.0})
    page.wait_for_function("Math.abs(window.peregrine.cursorT - 3.0) < 0.02", timeout=10000)
    page.wait_for_function("window.peregrine.plotView.own.t_s.length > 50")
    page.wait_for_function("window.peregrine.trackPoints >= 10", timeout=5000)  # main: 1
    clean(station)


# ---------------------------------------------------------------------- B: many sorties at once
def test_overlay_of_sorties_picked_on_the_sorties_page(station, page):
    clean(station)
    names = []
    for k_y, law in ((3, "png"), (4, "png"), (3, "pg")):
        api(station, "PUT", "/api/gains", {"K_y": k_y})
        names.append(fly(station, law=law))
    clean(station)
    page.goto(station.url())
    page.goto(base(station) + "sorties")
    for n in names:
        page.locator(f'#logs tbody tr[data-name="{n}"] input[data-sel]').check()
    assert page.text_content("#ov-go") == "Overlay selected (3)"
    page.click("#ov-go")
    page.wait_for_function("window.peregrine.openedMs !== null", timeout=60000)
    rows = page.locator("#ov-table tbody tr")
    assert rows.count() == 3
    # only the gains that differ: K_y (3, 4, 3), nothing else
    gains = [rows.nth(k).locator("td.gains").text_content() for k in range(3)]
    assert gains == ["K_y 3", "K_y 4", "K_y 3"]
    info = [api(station, "GET", f"/api/logs/{n}") for n in names]
    miss = [rows.nth(k).locator("td").nth(6).text_content() for k in range(3)]
    assert miss == [fmt_num(i["miss_m"]) for i in info]
    # every plot carries the three sorties, aligned on the intercept: each crosses t = 0 there
    series = page.evaluate("window.peregrine.plots.map(u => u.series.length)")
    assert series == [4, 4, 4, 4]
    xs = page.evaluate("window.peregrine.plots[3].data[0]")
    # (after the pass each sortie goes on for at most 6 s while the vehicle recovers)
    assert min(xs) < -4.0 and 0.0 <= max(xs) <= 6.5
    strokes = page.evaluate("window.peregrine.plots[0].series.slice(1).map(s => s._stroke)")
    assert len(set(strokes)) == 3
    page.select_option("#ov-align", "start")
    page.wait_for_function("Math.min(...window.peregrine.plots[3].data[0]) >= 0")
    # a scrub moves the cursor everywhere
    drawn = page.evaluate("window.peregrine.drawn")
    page.eval_on_selector(
        "#ov-scrub", "(el) => { el.value = 2.0; el.dispatchEvent(new Event('input')); }"
    )
    page.wait_for_function(f"window.peregrine.drawn > {drawn}")
    assert abs(page.evaluate("window.peregrine.cursor") - 2.0) < 0.02  # the slider's step
    # Re-fly: the Sorties page's form, prefilled with that sortie's gains
    rows.nth(1).locator("button[data-act=refly]").click()
    page.wait_for_selector("#refly-form:not([hidden])")
    assert page.input_value('#refly-gains input[data-gain="K_y"]') == "4"
    page.go_back()
    page.wait_for_function("window.peregrine.openedMs !== null", timeout=60000)
    # clicking a sortie opens it in the dashboard
    page.screenshot(path=str(station.log_dir.parent / "overlay.png"), full_page=True)
    page.locator("#ov-table tbody tr").nth(2).locator("a[data-act=open]").click()
    page.wait_for_function(
        f"window.peregrine.snap && window.peregrine.snap.status.replay"
        f" && window.peregrine.snap.status.replay.file === {names[2]!r}",
        timeout=15000,
    )
    clean(station)


# ---------------------------------------------------------------------- C: video in replay
def test_replay_video_frame_follows_200_random_seeks(station, page):
    import random

    from groundstation.recording.reader import iter_messages

    clean(station)
    s = station.session
    s.start(SortieConfig(load_scenario("cv-top-to-bottom"), "png", 0, "rendered", "max"))
    name = s.recording["file"]
    wait_state(station, "finished", timeout=120)
    frames = [t for _, t, _ in iter_messages(station.log_dir / name, ["/camera/image"])]
    assert len(frames) > 10
    api(station, "POST", "/api/replay/open", {"name": name})
    goto(page, station)
    duration = status(station)["replay"]["duration_s"]
    rng = random.Random(7)
    hits = 0
    for _ in range(200):  # backward and forward at random
        t = round(rng.uniform(0.0, duration), 3)
        api(station, "POST", "/api/replay/seek", {"t_s": t})
        page.wait_for_function(
            f"window.peregrine.frameFor !== undefined && Math.abs(window.peregrine.frameFor - {t})"
            " < 1e-6",
            timeout=10000,
        )
        shown = page.evaluate("window.peregrine.frameT")
        before = [f for f in frames if f <= t + 1e-6]
        expected = before[-1] if before and t - before[-1] <= 0.5 else None
        assert shown == (None if expected is None else round(expected, 6)), (t, shown, expected)
        hits += shown is not None and 0.0 <= t - shown < 0.2 + 1e-6  # within one frame (5/s)
    assert hits == 200
    clean(station)
