"""The dashboard in headless Chromium (Playwright driving Debian's chromium): the token is
required, a sortie runs, a gain edited on the page takes effect, the outcome shows."""

import re
import time
import urllib.request

import pytest

from groundstation.app.server import GroundStation
from onboard.enums import DEFAULT_LAW
from onboard.link.params import PARAM_SPECS

from .browser_support import needs_chromium

pytestmark = needs_chromium


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

    # the views follow the sortie while it flies (the rate is `groundstation bench
    # --dashboard`'s figure, not a timed assertion here: a loaded machine must not fail it)
    # every telemetry message of the running sortie is applied: one more point in the plots'
    # series per message counted (`bench --dashboard` prints applied, received and painted)
    probe = "[window.peregrine.applied, window.peregrine.plotView.own.t_s.length]"
    n0, t0 = page.evaluate("[window.peregrine.updates, window.peregrine.shownT]")
    a0, points0 = page.evaluate(probe)
    page.wait_for_function(
        f"window.peregrine.updates >= {n0 + 5} && window.peregrine.shownT > {t0 + 0.3}",
        timeout=10000,
    )
    a1, points1 = page.evaluate(probe)
    assert points1 - points0 == a1 - a0 >= 1
    assert page.evaluate("window.peregrine.received") >= a1
    page.select_option("#speed", "max")
    page.wait_for_function(
        "document.querySelector('#st-outcome').textContent.includes('miss')", timeout=30000
    )
    outcome = page.text_content("#st-outcome")
    # the realistic default sensors decide seed 0's outcome; the page must show the one flown
    flown = station.session.status()["outcome"]
    assert flown in ("HIT", "MISS") and outcome.startswith(flown), (outcome, flown)
    shot = tmp_path / "dashboard.png"
    page.screenshot(path=str(shot))
    assert shot.stat().st_size > 20000
    assert not errors, errors
    page.close()


def test_viser_scene_connects_through_the_proxy(station, browser):
    page = browser.new_page()
    page.goto(station.url())
    frame = page.frame_locator("#viser")
    frame.locator("text=View").first.wait_for(timeout=20000)  # per-viewer GUI from the server
    page.close()


def test_open_a_recorded_sortie_and_scrub(station, browser):
    from groundstation.app.session import SortieConfig
    from groundstation.scenario import load_scenario

    station.session.start(SortieConfig(load_scenario("cv-top-to-bottom"), speed="max"))
    deadline = time.monotonic() + 120  # the whole sortie: the next test finds it finished
    while station.session.state != "finished":
        assert time.monotonic() < deadline, "the sortie did not finish"
        time.sleep(0.1)
    page = browser.new_page(viewport={"width": 1500, "height": 1000})
    page.goto(station.url())
    page.goto(station.url().split("?")[0] + "sorties")
    page.wait_for_selector("#logs tbody tr", timeout=10000)
    row = page.locator("#logs tbody tr", has_text="cv-top-to-bottom").first
    flown = station.session.status()["outcome"]  # the realistic sensors decide seed 0's
    assert flown in ("HIT", "MISS") and flown in row.text_content()
    row.locator("button[data-act=open]").click()
    page.wait_for_url(re.compile(r"/$|/\?"))
    page.wait_for_selector("#replay-panel:not([hidden])", timeout=10000)
    for target in (1.5, 4.0, 2.5):  # scrub forward and back: the views follow
        page.eval_on_selector(
            "#rp-scrub",
            "(el, v) => { el.value = v; el.dispatchEvent("
            "new Event('input')); el.dispatchEvent(new Event('change')); }",
            target,
        )
        page.wait_for_function(
            f"window.peregrine.shownT !== undefined && "
            f"Math.abs(window.peregrine.shownT - {target}) < 0.05",
            timeout=10000,
        )
        assert f"t = {target:.2f} s" in page.text_content("#st-time")
    e_y = page.evaluate("window.peregrine.snap.e_est_px[1]")
    assert e_y is not None
    page.click("#rp-closest")  # the cursor goes to the recorded closest approach
    page.wait_for_function(
        "(r => r && Math.abs(r.t_s - r.closest_time_s) < 0.05)"
        "(window.peregrine.snap.status.replay)",
        timeout=10000,
    )
    t_ca = page.evaluate("window.peregrine.snap.status.replay.closest_time_s")
    assert 1.0 < t_ca < page.evaluate("window.peregrine.snap.status.replay.duration_s")
    assert f"t = {t_ca:.2f} s" in page.text_content("#st-time")
    page.close()


# ---------------------------------------------------------------------- live mode
class FakeOnboard:
    """Plays the onboard component on the ground link: heartbeat, telemetry, parameters,
    and COMMAND_ACK for start and abort."""

    def __init__(self, port: int) -> None:
        import threading

        from onboard.gains import Gains
        from onboard.link.params import PARAM_IDS, PARAM_SPECS
        from onboard.link.px4 import MavLink

        self.link = MavLink(f"udpout:127.0.0.1:{port}", 1, 191)
        self.values = {s.param_id: s.default for s in PARAM_SPECS}
        self.values.update({PARAM_IDS[k]: v for k, v in Gains().to_dict().items()})
        self.names = [s.param_id for s in PARAM_SPECS]
        self.state = 2  # ready
        self.commands: list[int] = []
        self.hold_param_sets = threading.Event()  # set: PARAM_SETs kept unanswered until clear
        self.param_sets: list[tuple[str, float]] = []
        self._held: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import time

        from onboard.link import telemetry as tm
        from onboard.link.px4 import CMD_START, mavlink

        t0 = time.monotonic()
        k = 0
        while not self._stop.is_set():
            link = self.link
            msgs = link.poll()
            if not self.hold_param_sets.is_set():
                msgs, self._held = self._held + msgs, []
            for m in msgs:
                kind = m.get_type()
                if kind == "PARAM_SET" and self.hold_param_sets.is_set():
                    self._held.append(m)
                    continue
                if kind == "PARAM_REQUEST_LIST":
                    for i, n in enumerate(self.names):
                        link.send(link.mav.param_value_encode(n.encode(), self.values[n], 9,
                                                              len(self.names), i))  # fmt: skip
                elif kind == "PARAM_SET":
                    name = m.param_id
                    self.param_sets.append((name, m.param_value))
                    if name == "PRG_K_P" and 0.0 <= m.param_value <= 0.2:
                        self.values[name] = m.param_value
                    link.send(link.mav.param_value_encode(
                        name.encode(), self.values[name], 9, len(self.names),
                        self.names.index(name)))  # fmt: skip
                elif kind == "COMMAND_LONG":
                    self.commands.append(m.command)
                    if m.command == CMD_START:
                        self.state = 4
                    link.send(link.mav.command_ack_encode(m.command, 0, 0, 0, 255, 190))
            t = time.monotonic() - t0
            if k % 20 == 0:
                link.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, self.state, 3)
            vals = {"t_s": t, "state": self.state, "loop_mode": 1, "e_est_u_px": 20.0,
                    "e_est_v_px": -10.0, "pos_e_m": 0.0, "pos_n_m": t, "pos_u_m": 10.0,
                    "vel_e_m_s": 0.0, "vel_n_m_s": 1.0, "vel_u_m_s": 0.0, "image_w_px": 640,
                    "image_h_px": 480, "f_px": 320.0, "loop_rate_hz": 200.0,
                    "loop_jitter_p99_ms": 0.8, "latency_ms": 86.0}  # fmt: skip
            link.send(link.mav.debug_float_array_encode(int(t * 1e6), b"PRG_CTRL", 1,
                                                        tm.pack(vals)))  # fmt: skip
            k += 1
            time.sleep(0.05)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.link.close()


def test_live_mode_panel_start_abort_and_gain_round_trip(browser, tmp_path):
    port = free_udp_port()
    gs = GroundStation(port=0, data_dir=tmp_path, log_dir=tmp_path / "logs",
                       mavlink_url=f"udpin:127.0.0.1:{port}")  # fmt: skip
    gs.start_in_thread()
    fake = FakeOnboard(port)
    n = len(PARAM_SPECS)  # the whole parameter table arrives
    page = browser.new_page(viewport={"width": 1500, "height": 1000})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.goto(gs.url())
        page.wait_for_selector("#live-panel:not([hidden])", timeout=15000)
        assert page.is_hidden("#sim-panel")
        page.wait_for_function("document.querySelector('#lv-link').textContent === 'up'")
        page.wait_for_function(
            f"document.querySelector('#lv-params').textContent.startsWith('{n}/{n}')",
            timeout=10000,
        )
        assert page.text_content("#lv-state") == "ready"
        assert "DEBUG_FLOAT_ARRAY" in page.text_content("#lv-rates")
        page.wait_for_function("window.peregrine.snap && window.peregrine.snap.e_est_px")

        # a gain edit goes out as PARAM_SET; the page shows it once PARAM_VALUE is back
        page.wait_for_function("document.querySelectorAll('#gains input').length > 5")
        page.fill('#gains input[data-gain="k_p"]', "0.05")
        page.click("#btn-apply-gains")
        deadline = time.monotonic() + 10.0  # the PARAM_SET reaches the vehicle, its reply us
        while time.monotonic() < deadline and not (
            fake.values["PRG_K_P"] == pytest.approx(0.05) and gs.session.gains.k_p == 0.05
        ):
            time.sleep(0.05)
        live = gs.session.status()["live"]  # which end of the round trip stalled, if one did
        assert fake.values["PRG_K_P"] == pytest.approx(0.05), (fake.param_sets, live)
        assert gs.session.gains.k_p == 0.05, live  # the float32 on the wire, read back as 0.05
        page.wait_for_function(
            "document.querySelector('#gains input[data-gain=\"k_p\"]').value === '0.05'"
            " && !document.querySelector('#gains-applied').textContent.includes('waiting')",
            timeout=10000,
        )
        page.wait_for_function(  # every gain shown as the decimal it is, not float32 noise
            "[...document.querySelectorAll('#gains input')].every(i => i.value.length < 8)"
        )

        page.click("#btn-live-start")
        page.wait_for_function(
            "document.querySelector('#live-msg').textContent === 'start: accepted'"
        )
        page.wait_for_function("document.querySelector('#lv-state').textContent === 'intercept'")
        # the vehicle's state can reach the page in a status update sent before the
        # acknowledgement was taken in; the next update shows it
        page.wait_for_function(
            "document.querySelector('#lv-ack').textContent === 'start: accepted'", timeout=5000
        )
        page.click("#btn-live-abort")
        page.wait_for_function(
            "document.querySelector('#live-msg').textContent === 'abort: accepted'"
        )
        assert fake.commands == [31010, 31011]
        page.screenshot(path=str(tmp_path / "live.png"))
        assert not errors, errors
    finally:
        page.close()
        fake.close()
        gs.stop()


def test_a_gain_read_answered_late_does_not_put_back_the_value_replaced(browser, tmp_path):
    """After Apply the page reads the gains in force twice: once when the PUT returns (the
    vehicle has not answered yet: the old value) and again when the vehicle's PARAM_VALUE
    is in. Answered in the other order, the field still shows the value the vehicle flies."""
    port = free_udp_port()
    gs = GroundStation(port=0, data_dir=tmp_path, log_dir=tmp_path / "logs",
                       mavlink_url=f"udpin:127.0.0.1:{port}")  # fmt: skip
    gs.start_in_thread()
    fake = FakeOnboard(port)
    n = len(PARAM_SPECS)
    page = browser.new_page(viewport={"width": 1500, "height": 1000})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    reads = []  # k_p in each read after Apply, as the server answered it
    after_apply = {"on": False, "held": None}  # the first read's route and answer

    def gains_read(route):
        if route.request.method != "GET" or not after_apply["on"]:
            return route.continue_()
        answer = route.fetch()
        reads.append(answer.json()["values"]["k_p"])
        if len(reads) == 1:
            after_apply["held"] = (route, answer)  # the first read after Apply: held back
            return None
        route.fulfill(response=answer)  # the later read answered first
        held, held_answer = after_apply["held"]
        held.fulfill(response=held_answer)  # then the earlier one, its value now stale
        return None

    try:
        page.route(re.compile(r".*/api/gains(\?.*)?$"), gains_read)
        page.goto(gs.url())
        page.wait_for_function(
            f"document.querySelector('#lv-params').textContent.startsWith('{n}/{n}')",
            timeout=15000,
        )
        page.wait_for_function("document.querySelectorAll('#gains input').length > 5")
        assert page.input_value('#gains input[data-gain="k_p"]') == "0.03"
        fake.hold_param_sets.set()  # the vehicle answers once the first read is out
        after_apply["on"] = True
        page.fill('#gains input[data-gain="k_p"]', "0.05")
        page.click("#btn-apply-gains")
        deadline = time.monotonic() + 10.0
        while after_apply["held"] is None and time.monotonic() < deadline:
            page.wait_for_timeout(20)
        assert reads == [pytest.approx(0.03)], reads
        assert ("PRG_K_P", pytest.approx(0.05)) not in fake.param_sets  # not answered yet
        fake.hold_param_sets.clear()
        page.wait_for_function(
            "document.querySelector('#gains-applied').textContent.includes('applied at t =')",
            timeout=10000,
        )
        while len(reads) < 2 and time.monotonic() < deadline + 10.0:
            page.wait_for_timeout(20)
        assert reads == [pytest.approx(0.03), pytest.approx(0.05)]
        page.wait_for_timeout(300)  # both answers taken in by the page
        assert page.input_value('#gains input[data-gain="k_p"]') == "0.05"
        assert gs.session.gains.k_p == 0.05
        assert not errors, errors
    finally:
        page.close()
        fake.close()
        gs.stop()


def free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_option_lists_come_from_the_api_and_the_chosen_law_flies(station, browser):
    # the module's earlier tests leave a sortie or a replay and a speed: start from the defaults
    station.session.reset()
    station.session.set_speed("1")
    page = browser.new_page(viewport={"width": 1500, "height": 1000})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(station.url())
    page.wait_for_selector("text=telemetry: live", timeout=15000)
    meta = page.evaluate("window.peregrineMeta")
    for sel, key in (("#law", "laws"), ("#camera", "camera_modes"), ("#speed", "speeds")):
        shown = page.eval_on_selector(sel, "s => [...s.options].map(o => o.value)")
        assert shown == meta[key], (sel, shown)
    for sel, key in (("#law", "laws"), ("#camera", "camera_modes"), ("#speed", "speeds")):
        assert page.eval_on_selector(sel, "s => s.value") == meta["defaults"][key], sel
    assert meta["defaults"]["laws"] == DEFAULT_LAW.value  # the page starts on the flown default
    page.select_option("#scenario", "static-ahead-20m")
    page.select_option("#law", "pg")
    page.select_option("#speed", "max")
    page.click("#btn-start")
    page.wait_for_function(  # this sortie's end, not an earlier one still on screen
        "(s => s && s.status.state === 'finished' && s.status.law === 'pg')(window.peregrine.snap)",
        timeout=30000,
    )
    assert station.session.sim.law == "pg"  # what flew is what was chosen
    assert station.session.status()["law"] == "pg"
    page.goto(station.url().split("?")[0] + "sorties")
    page.wait_for_function("document.querySelector('#refly-law').options.length > 0")
    refly = page.eval_on_selector("#refly-law", "s => [...s.options].map(o => o.value)")
    assert refly == meta["laws"]
    assert not errors, errors
    page.close()
