"""Scenario files: strict loading, clear errors, exit status 2 without a traceback."""

import pytest

from groundstation.cli import main
from groundstation.scenario import ScenarioError, load_scenario, parse_scenario, shipped_scenarios

from .cli_support import run_cli

GOOD = """
name = "cv-top-to-bottom"
duration_s = 30
[interceptor]
position_m = [0.0, 0.0, 10.0]
velocity_m_s = [0.0, 0.0, 0.0]
yaw_deg = 90.0
[target]
motion = "cv"
position_m = [0.0, 25.0, 1.0]
velocity_m_s = [0.0, 0.0, 1.0]
acceleration_m_s2 = [0.0, 0.0, 0.0]
amplitude_m = [2.0, 0.0, 0.0]
period_s = 14.0
diameter_m = 0.3
[camera]
[wind]
mean_m_s = [0.0, 0.0, 0.0]
gust_m_s = 0.0
"""


def test_the_documented_example_parses():
    s = parse_scenario(GOOD, "ex.toml")
    assert s.name == "cv-top-to-bottom" and s.duration_s == 30.0
    assert s.target.velocity_m_s == (0.0, 0.0, 1.0)
    assert s.camera.width_px == 640 and s.camera.hfov_deg == 90.0  # DESIGN §6 defaults


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("yaw_deg = 90.0", "yaw_deg = 90.0\nyaw_rate = 1"), "unknown key 'interceptor.yaw_rate'"),
        (('motion = "cv"\n', ""), "missing required key 'target.motion'"),
        (("duration_s = 30", 'duration_s = "30"'), "key 'duration_s': expected a number"),
        (("position_m = [0.0, 25.0, 1.0]", "position_m = [0.0, 25.0]"), "key 'target.position_m'"),
        (("gust_m_s = 0.0", "gust_m_s = true"), "key 'wind.gust_m_s': expected a number"),
        (('motion = "cv"', 'motion = "teleport"'), "key 'target.motion': must be one of"),
        (("[camera]", "[camera]\nrate_hz = 7"), "key 'camera.rate_hz': 7.0 Hz must divide"),
        (("name =", "nam ="), "unknown key 'nam'"),
        (("[wind]", "[gains]\nK_y = 50\n[wind]"), "gain K_y = 50.0 is outside its range"),
        (("[camera]", "[camera\n"), "not valid TOML"),
    ],
)
def test_errors_name_the_key_and_the_file(edit, message):
    text = GOOD.replace(*edit)
    assert text != GOOD
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(text, "bad.toml")
    assert str(exc.value).startswith("bad.toml: ")
    assert message in str(exc.value)


def test_cli_bad_file_exits_2_without_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(GOOD.replace("[target]", "[target]\nspeed = 3"))
    code, out, err = run_cli(main, ["sortie", str(bad), "--json"], capsys)
    assert code == 2
    assert "unknown key 'target.speed'" in err and str(bad) in err
    assert "Traceback" not in err and out == ""
    code, _, err = run_cli(main, ["sortie", str(tmp_path / "nope.toml")], capsys)
    assert code == 2 and "no such file or shipped scenario" in err


def test_every_shipped_scenario_loads_and_names_match_files():
    paths = shipped_scenarios()
    assert len(paths) >= 12
    for p in paths:
        s = load_scenario(p)
        assert s.name == p.stem
        assert s.description


def test_shipped_name_lookup():
    assert load_scenario("cv-top-to-bottom").target.motion == "cv"


def _values(s):
    import dataclasses

    d = dataclasses.asdict(s)
    d.pop("source"), d.pop("text")
    return d


@pytest.mark.parametrize("path", shipped_scenarios(), ids=lambda p: p.stem)
def test_a_changed_scenario_writes_toml_that_reads_back_equal(path):
    from groundstation.scenario import scenario_toml, with_overrides

    s = load_scenario(path)
    text = scenario_toml(s)  # unchanged: the file as read, comments and all, ...
    assert text.startswith(s.text)
    if "[estimate]" not in s.text:  # ... with the estimate settings that apply appended
        assert "[estimate]" in text[len(s.text) :]
    assert _values(parse_scenario(text)) == _values(s)
    changed = with_overrides(s, {"camera.noise_px": 0, "target.position_m": [1, 2, 3.5]})
    assert changed.camera.noise_px == 0.0 and changed.target.position_m == (1.0, 2.0, 3.5)
    assert changed.text == "" and changed.source == s.source
    again = parse_scenario(scenario_toml(changed))
    assert _values(again) == _values(changed)


def test_overrides_are_checked_like_the_file():
    from groundstation.scenario import parse_overrides, with_overrides

    s = load_scenario("static-ahead-20m")
    assert parse_overrides(["camera.delay_s=0", "gains.k_v = 100", 'name="x"']) == {
        "camera.delay_s": 0,
        "gains.k_v": 100,
        "name": "x",
    }
    o = with_overrides(s, parse_overrides(["camera.delay_s=0", "gains.k_v=100", "duration_s=9"]))
    assert (o.camera.delay_s, o.gains["k_v"], o.duration_s) == (0.0, 100.0, 9.0)
    assert o.camera.noise_px == s.camera.noise_px  # the rest of the section is kept
    for items, message in (
        (["camera.delay_s"], "expected SECTION.KEY=VALUE"),
        (["camera.delay_s=fast"], "camera.delay_s: 'fast' is not a value"),
        (["gains.k_v=abc"], "gains.k_v: 'abc' is not a value"),
        (["=1"], "expected SECTION.KEY=VALUE"),
    ):
        with pytest.raises(ScenarioError, match=message):
            parse_overrides(items)
    for overrides, message in (
        ({"camera.delay_s": "0"}, "camera.delay_s': expected a number"),
        ({"camera.rate_hz": 7}, "must divide the physics rate"),
        ({"optics.f": 1}, "unknown section 'optics'"),
        ({"speed": 1}, "unknown key 'speed'"),
        ({"target.position_m": [1, 2]}, "expected a list of 3 numbers"),
        ({"gains.k_a": -1}, "outside its range"),
        ({"gains.k_a": True}, "expected a number"),
    ):
        with pytest.raises(ScenarioError, match=message):
            with_overrides(s, overrides)
