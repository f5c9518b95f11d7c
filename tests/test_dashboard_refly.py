"""Re-fly and compare in the browser: a re-fly runs at 1x with the old sortie overlaid and a
legend that names only the gains that differ, its gains fly that sortie only, a compare named
in the URL or asked from an idle page is drawn, and a reload restores the sortie so far and the
controls in force. Rules: docs/operator-gains.md."""

import re
import time

import pytest

from groundstation.app.numbers import fmt_num
from groundstation.app.session import SortieConfig
from groundstation.scenario import load_scenario

from .browser_support import needs_chromium
from .dashboard_support import (
    api,
    base,
    clean,
    fly,
    goto,
    plot_t,
    recorded_gains,
    status,
    wait_state,
)

pytestmark = needs_chromium


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
    time.sleep(2.0)
    rate = (status(station)["time_s"] - t0) / (time.monotonic() - w0)
    # at 1x it can be watched; at the maximum speed it runs tens of times faster than the
    # wall clock (the bounds leave room for a busy machine's scheduling and the stepped clock)
    assert 0.3 < rate < 3.0, rate
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
    # the Sorties page shows the lineage and the columns an operator sorts by
    page.goto(base(station) + "sorties")
    row = page.locator(f'#logs tbody tr[data-name="{reflown}"]')
    assert f"re-flown from {name}" in row.text_content()
    cells = row.locator("td").all_text_contents()
    assert cells[1:5] == ["cv-top-to-bottom", "pg", "projected", "0"]
    page.fill("#filter", "no-such-sortie")
    assert page.text_content("#empty") == 'No sortie matches "no-such-sortie".'


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
    # the controls follow the first status the page draws (on its next animation frame)
    page.wait_for_function("document.querySelector('#speed').value === '1'", timeout=15000)
    assert page.input_value("#law") == "pg"  # what flies, not the page's default
    assert page.input_value("#seed") == "3"
    station.session.reset()


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
