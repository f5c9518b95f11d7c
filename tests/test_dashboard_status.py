"""What the dashboard's header, message line and banners say: the recording file and a
write error or an unusable log folder as a banner, the status line to the sortie's end, no
stale text after a reset, one rounding rule for the miss everywhere, ideal sensors labelled."""

from groundstation.app.numbers import fmt_num
from groundstation.app.session import SortieConfig
from groundstation.scenario import load_scenario

from .browser_support import needs_chromium
from .dashboard_support import base, clean, fly, goto, status, wait_state

pytestmark = needs_chromium


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
