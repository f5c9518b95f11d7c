"""The gains panel in the browser never lies about the gains flying: an edit is flown at
Start, a typed value is applied by Start, Apply names every refusal, gain sets round-trip, the
panel is grouped and searchable, and a study's trial flies its gains for that sortie only.
Rules: docs/operator-gains.md."""

import time
from pathlib import Path

import pytest

from groundstation.app.session import SortieConfig
from groundstation.scenario import load_scenario

from .as_written import load_as_written
from .browser_support import needs_chromium
from .dashboard_support import api, clean, goto, recorded_gains, status, wait_state

pytestmark = needs_chromium


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


def test_a_typed_gain_is_applied_by_start_and_a_bad_one_refuses_the_start(station, page):
    clean(station)
    goto(page, station)
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "max")
    page.fill('#gains input[data-gain="K_z"]', "4")  # typed, Apply not pressed
    # every text the message line shows: the telemetry's "started" can come before Start's
    # answer, which names the typed value, and at max speed "finished" soon after it
    page.evaluate(
        "window.simMsgs = []; new MutationObserver(() => window.simMsgs.push("
        "document.querySelector('#sim-msg').textContent)).observe("
        "document.querySelector('#sim-msg'), {childList: true, characterData: true, subtree: true})"
    )
    page.click("#btn-start")
    shown = "started, with your typed value applied: K_z = 4"
    page.wait_for_function(f"window.simMsgs.includes({shown!r})")
    assert station.session.sim.loop.gains.K_z == 4.0  # main: 3, the typed value discarded
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
    # the Apply refusal above already left the message marked as an error: wait for the new one
    page.wait_for_function(
        "document.querySelector('#gains-msg').textContent.startsWith('gain set file')"
    )
    assert "err" in page.get_attribute("#gains-msg", "class")
    text = page.text_content("#gains-msg")
    assert text.startswith("gain set file 'broken' refused, nothing saved: 3 problems:")
    assert "K_y" in text and "foo" in text and "K_z" in text and "uploaded" not in text
    assert "broken" not in api(station, "GET", "/api/gainsets")
    clean(station)


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
