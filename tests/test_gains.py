import math

import pytest

from onboard.cli import main
from onboard.gains import GAIN_NAMES, GAIN_SPECS, GainError, Gains

from .cli_support import run_cli


def test_defaults_are_the_papers_flight_values():
    g = Gains()
    assert (g.k_a, g.K_y, g.K_z, g.k_p, g.k_d) == (2.0, 3.0, 3.0, 0.03, 0.01)


def test_every_gain_declared_with_unit_range_and_meaning():
    for s in GAIN_SPECS:
        assert s.unit and s.meaning and s.minimum <= s.default <= s.maximum
        assert len(s.name) <= 16


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"K_y": 11.0}, "gain K_y = 11.0 is outside its range"),
        ({"k_p": -0.1}, "gain k_p"),
        ({"a_max": math.nan}, "gain a_max: nan is not finite"),
        ({"k_a": "2"}, "gain k_a: expected a number"),
        ({"k_a": True}, "gain k_a: expected a number"),
        ({"bogus": 1.0}, "unknown gain(s): bogus"),
    ],
)
def test_bad_gains_are_refused_naming_the_gain(changes, message):
    with pytest.raises(GainError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Gains().replace(**changes)


def test_from_mapping_names_the_source():
    with pytest.raises(GainError, match=r"^flight\.toml: gain v_max"):
        Gains.from_mapping({"v_max": 100}, source="flight.toml")
    assert Gains.from_mapping({"v_max": 8}).v_max == 8.0
    assert set(Gains().to_dict()) == set(GAIN_NAMES)


def test_onboard_gains_cli(tmp_path, capsys):
    good = tmp_path / "good.toml"
    good.write_text("k_p = 0.05\nK_y = 4\n")
    code, out, err = run_cli(main, ["gains", "--check", str(good)], capsys)
    assert code == 0, err
    assert "k_p" in out and "0.05" in out
    bad = tmp_path / "bad.toml"
    bad.write_text("k_p = 5\n")
    code, _, err = run_cli(main, ["gains", "--check", str(bad)], capsys)
    assert code == 2
    assert "gain k_p = 5 is outside its range" in err and "Traceback" not in err
