"""The dashboard in headless Chromium (Playwright driving Debian's chromium): the token is
required, a sortie runs, a gain edited on the page takes effect, the outcome shows."""

import re
import shutil
import urllib.request

import pytest

from groundstation.app.server import GroundStation

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed")
ARGS = [
    "--no-sandbox",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    gs = GroundStation(port=0, data_dir=tmp_path_factory.mktemp("gs"))
    gs.start_in_thread()
    yield gs
    gs.stop()


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def test_page_refused_without_token(station, browser):
    base = station.url().split("?")[0]
    page = browser.new_page()
    resp = page.goto(base)
    assert resp.status == 401
    assert "Access token required" in page.content()
    with pytest.raises(urllib.error.HTTPError) as exc:
        urllib.request.urlopen(base + "api/status")
    assert exc.value.code == 401
    page.close()


def test_operator_flies_cv_and_edits_a_gain(station, browser, tmp_path):
    page = browser.new_page(viewport={"width": 1500, "height": 1000})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(station.url())
    page.wait_for_selector("text=telemetry: live", timeout=15000)
    page.wait_for_function("document.querySelectorAll('#gains input').length > 5")
    page.select_option("#scenario", "cv-top-to-bottom")
    page.select_option("#speed", "1")
    page.click("#btn-start")
    page.wait_for_function("window.peregrine.snap && window.peregrine.snap.t > 0.5", timeout=15000)

    # an out-of-range value is refused on the page and the running value stays
    page.fill('#gains input[data-gain="k_p"]', "7")
    page.click("#btn-apply-gains")
    page.wait_for_selector("#gains-msg.err", timeout=5000)
    assert "k_p" in page.text_content("#gains-msg")
    assert station.session.sim.loop.gains.k_p == 0.03

    # a good value takes effect at the next control tick of the running sortie
    page.fill('#gains input[data-gain="k_p"]', "0.05")
    page.click("#btn-apply-gains")
    page.wait_for_function(
        "document.querySelector('#gains-applied').textContent.includes('applied at t =')",
        timeout=10000,
    )
    assert station.session.sim.loop.gains.k_p == 0.05
    applied = float(re.search(r"t = ([\d.]+)", page.text_content("#gains-applied")).group(1))
    assert 0.5 < applied < 10.0

    # the views update while it flies
    n0 = page.evaluate("window.peregrine.updates")
    page.wait_for_timeout(1000)
    assert page.evaluate("window.peregrine.updates") - n0 >= 15
    page.select_option("#speed", "max")
    page.wait_for_function(
        "document.querySelector('#st-outcome').textContent.includes('miss')", timeout=30000
    )
    outcome = page.text_content("#st-outcome")
    assert outcome.startswith("HIT"), outcome
    shot = tmp_path / "dashboard.png"
    page.screenshot(path=str(shot))
    assert shot.stat().st_size > 20000
    assert not errors, errors
    page.close()


def test_viser_scene_connects_through_the_proxy(station, browser):
    page = browser.new_page()
    page.goto(station.url())
    frame = page.frame_locator("#viser")
    frame.locator("text=Follow vehicle").wait_for(timeout=20000)  # GUI from the server
    page.close()
