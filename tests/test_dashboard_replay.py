"""Recorded sorties in the browser: the Sorties page (empty, campaign subfolders, several
sorties overlaid), a replay's plots hold the whole sortie and a seek moves only the cursor, the
replay runs at the speed shown, a reload keeps its place, and the video frame follows random
seeks. One ground station and one headless chromium serve every test of this module; the first
test needs the station with nothing recorded yet."""

import random
import re
import shutil
import time

import pytest

from groundstation.app.numbers import fmt_num
from groundstation.app.session import SortieConfig
from groundstation.scenario import load_scenario

from .browser_support import needs_chromium
from .dashboard_support import api, base, clean, fly, goto, plot_t, status, wait_state

pytestmark = needs_chromium


def test_sorties_page_says_when_there_is_nothing_to_show(station, page):
    page.goto(station.url())
    page.goto(base(station) + "sorties")
    page.wait_for_selector("#empty:not([hidden])")
    assert page.text_content("#empty").startswith("No recorded sorties yet.")
    assert page.text_content("#count") == "0 of 0 sorties"


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

    # "v normal to LOS" is computed from the recorded frame
    vn = series["columns"]["normal_vel_m_s"]
    assert sum(v is not None for v in vn) > 0.9 * len(vn)
    assert page.evaluate("window.peregrine.snap.normal_vel_m_s") is not None
    assert max(v for v in vn if v is not None) > 0.5
    # file names keep their case
    assert page.eval_on_selector("#rp-file", "e => getComputedStyle(e).textTransform") == "none"
    assert name in page.text_content("#rp-file")


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


def test_reload_in_replay_keeps_the_position_and_the_plots(station, page):
    name = fly(station)
    api(station, "POST", "/api/replay/open", {"name": name})
    api(station, "POST", "/api/replay/seek", {"t_s": 2.0})
    goto(page, station)
    page.wait_for_function("Math.abs(window.peregrine.cursorT - 2.0) < 0.02", timeout=10000)
    assert float(page.input_value("#rp-scrub")) == pytest.approx(2.0)
    assert plot_t(page)[-1] > 5.0


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
    # the predicate may first run on the Sorties page, which has no window.peregrine
    with page.expect_navigation(url="**/overlay?*"):
        page.click("#ov-go")
    page.wait_for_function("window.peregrine && window.peregrine.openedMs != null", timeout=60000)
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
    page.wait_for_url("**/overlay?*")
    page.wait_for_function("window.peregrine && window.peregrine.openedMs != null", timeout=60000)
    # clicking a sortie opens it in the dashboard
    page.screenshot(path=str(station.log_dir.parent / "overlay.png"), full_page=True)
    page.locator("#ov-table tbody tr").nth(2).locator("a[data-act=open]").click()
    page.wait_for_function(
        # the predicate may first run on the overlay page, whose window.peregrine has no snap
        f"window.peregrine && window.peregrine.snap && window.peregrine.snap.status.replay"
        f" && window.peregrine.snap.status.replay.file === {names[2]!r}",
        timeout=15000,
    )
    clean(station)


def test_replay_video_frame_follows_random_seeks_and_frame_edges(station, page):

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
    # backward and forward at random, the start and the end, and both sides of frame edges:
    # on a frame's time it is shown, a millisecond before it the previous one still is
    seeks = [round(rng.uniform(0.0, duration), 3) for _ in range(30)] + [0.0, duration]
    for f in rng.sample(frames[1:], 4):
        seeks += [round(f, 3), round(f - 0.001, 3)]
    rng.shuffle(seeks)
    hits = 0
    for t in seeks:
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
    assert hits == len(seeks) == 40
    clean(station)
