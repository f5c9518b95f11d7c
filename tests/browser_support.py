"""What every browser test module shares: Debian's chromium (a failure with ``CI`` set, a
skip elsewhere), its flags, one ground station and one browser per module, and a page whose
script errors fail the test."""

import os
import shutil

import pytest

from groundstation.app.server import GroundStation

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None and not os.environ.get("CI"),
    reason="Debian's chromium is not installed (with CI set this is a failure)",
)
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
    d = tmp_path_factory.mktemp("gs")
    gs = GroundStation(port=0, data_dir=d, log_dir=d / "logs")
    gs.start_in_thread()
    yield gs
    gs.stop()


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    if CHROMIUM is None:
        pytest.fail("CI is set and Debian's chromium is not installed")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


# The 3D view's page (viser, /viser/ on its own port) answered with an empty page: a test
# of the dashboard's other parts does not draw WebGL in software, a quarter of a browser
# test's CPU. The tests of the 3D view open their pages from ``browser`` and get it whole.
_NO_SCENE = "<!doctype html><title>3D view not loaded by this test</title>"


@pytest.fixture
def page(station, browser):
    """A new page of the module's browser, without the 3D view; a script error on it fails
    the test."""
    pg = browser.new_page(viewport={"width": 1500, "height": 1100})
    pg.errors = []
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    pg.route("**/viser/**", lambda r: r.fulfill(content_type="text/html", body=_NO_SCENE))
    yield pg
    errors = pg.errors
    pg.close()
    assert not errors, errors
