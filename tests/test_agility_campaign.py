"""Campaign ``agility`` (groundstation/campaigns/agility.py): its cells, the pairing of laws,
the summary's statistics and its report, on built jobs and made-up outcomes (no sorties)."""

from __future__ import annotations

import math

import pytest

from groundstation.campaigns import agility
from groundstation.campaigns.definitions import build_jobs, parse_only
from groundstation.campaigns.runner import SortieOutcome


def test_cells_and_paired_laws():
    jobs = build_jobs("agility", n=2, laws=("png", "apn"), seed=3)
    cells = len(agility.TURN_ACCELS_M_S2) + len(agility.JINK_RANGES_M)
    assert len(jobs) == cells * 2 * 2
    by_try: dict[tuple, dict[str, object]] = {}
    for j in jobs:
        lab = dict(j.labels)
        by_try.setdefault((lab["kind"], lab["value"], lab["try"]), {})[lab["law"]] = j
        t = j.scenario.target
        r = math.dist(t.position_m, agility.START_M)
        assert agility.RANGE_M[0] <= r <= agility.RANGE_M[1]
        if lab["kind"] == "turn":
            assert t.motion == "turn" and abs(t.lateral_accel_m_s2) == lab["value"]
            assert math.hypot(*t.velocity_m_s[:2]) == pytest.approx(agility.TURN_SPEED_M_S)
        else:
            assert t.motion == "jink" and t.trigger_range_m == lab["value"]
            assert t.velocity_m_s == (0.0, 0.0, 0.0) and t.side == 0.0
    for pair in by_try.values():  # the same target draw and seed for every law
        png, apn = pair["png"], pair["apn"]
        assert png.scenario.target == apn.scenario.target and png.seed == apn.seed
    assert build_jobs("agility", n=2, laws=("png",), seed=3)[0].scenario.target == (
        jobs[0].scenario.target
    )


def test_only_flies_a_subset_with_the_whole_campaigns_draws_and_seeds():
    whole = build_jobs("agility", n=3, laws=("png", "apn"), seed=5)
    only = parse_only(["kind=turn", "value=3,7.5"])
    assert only == {"kind": ("turn",), "value": ("3", "7.5")}
    part = build_jobs("agility", n=3, laws=("png", "apn"), seed=5, only=only)
    assert [j.index for j in part] == list(range(12))  # 2 values x 3 tries x 2 laws
    same = [
        j for j in whole if dict(j.labels)["kind"] == "turn" and dict(j.labels)["value"] in (3, 7.5)
    ]
    assert [(j.labels, j.scenario, j.seed, j.law) for j in part] == [
        (j.labels, j.scenario, j.seed, j.law) for j in same
    ]
    jinks = build_jobs("agility", n=1, laws=("apn",), seed=5, only=parse_only(["kind=jink"]))
    assert [dict(j.labels)["value"] for j in jinks] == list(agility.JINK_RANGES_M)


def test_wilson_interval():
    lo, hi = agility.wilson_interval(9, 10)
    assert lo == pytest.approx(0.5958, abs=1e-4) and hi == pytest.approx(0.9821, abs=1e-4)
    assert agility.wilson_interval(0, 20)[0] == 0.0 and agility.wilson_interval(20, 20)[1] == 1.0


def _outcome(i, kind, value, law, hit, miss):
    labels = {"kind": kind, "value": value, "law": law, "try": i}
    return SortieOutcome(i, labels, {"outcome": "HIT" if hit else "MISS", "miss_m": miss})


def test_summary_report_and_plot(tmp_path):
    outs = [_outcome(i, "turn", 5.0, "apn", i < 9, 0.1 if i < 9 else 0.8) for i in range(10)]
    outs += [_outcome(i, "jink", 8.0, "apn", i < 5, 0.2 + 0.1 * i) for i in range(10)]
    s = agility.summarize(outs)
    avail = s["available_accel_m_s2"]
    assert avail == pytest.approx(9.81, rel=1e-9)  # tilt 45 deg caps the default airframe
    turn = s["cells"]["turn"]["5"]["apn"]
    assert turn["success_rate"] == 0.9 and turn["mean_m"] == pytest.approx(0.17)
    assert turn["success_95"] == pytest.approx(agility.wilson_interval(9, 10))
    assert turn["accel_ratio"] == pytest.approx(5.0 / avail)
    assert s["cells"]["jink"]["8"]["apn"]["outcomes"] == {"HIT": 5, "MISS": 5}
    md = agility.markdown(s)
    assert "| 5 (0.51 of avail.) | 90 % (60-98), 0.17 m |" in md
    assert "| 8 | 50 % (24-76), 0.65 m |" in md
    assert agility.plots(s, tmp_path) == ["agility.png"]
    assert (tmp_path / "agility.png").stat().st_size > 10_000
