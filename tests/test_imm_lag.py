"""groundstation.bench.imm_lag: the share and delay of the IMM's acceleration against the truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.bench.imm_lag import main, share_and_delay


def _rows(scale: float, delay_s: float) -> np.ndarray:
    """A turn's acceleration across the line of sight (5 m/s^2 turning at 1 rad/s) and an
    estimate holding ``scale`` of it ``delay_s`` late, t_go from 4 s down to 0."""
    t = np.arange(0.0, 4.0, 0.01)
    true = 5.0 * np.stack([np.cos(t), np.sin(t), 0.0 * t], 1)
    td = t - delay_s
    est = scale * 5.0 * np.stack([np.cos(td), np.sin(td), 0.0 * t], 1)
    return np.column_stack([t, 4.0 - t, true, est])


def test_share_and_delay_of_a_scaled_late_estimate():
    share, d, fit = share_and_delay([_rows(0.6, 0.3)], 0.0, 2.0)
    assert d == pytest.approx(0.3, abs=1e-9)
    assert fit == pytest.approx(0.6, rel=1e-3)
    assert share == pytest.approx(0.6 * math.cos(0.3), rel=1e-3)  # 0.3 rad behind


def test_bad_input_is_refused(capsys):
    for argv in (["--n", "0"], ["--value", "nan"], ["--kind", "turn", "--value", "4"]):
        with pytest.raises(SystemExit):
            main(argv)
    assert "no cell" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["--set", "gains.nope=1"])
    assert e.value.code == 2 and "unknown gain(s): nope" in capsys.readouterr().err
