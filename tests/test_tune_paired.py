"""The tuning study's statistics: the ``success-mean`` objective (HIT rate first, then the
mean miss) and the paired comparison of two gain sets flown on the same sorties (per-sortie
differences, bootstrap CI, sign test), also over two ``campaign`` runs' results.json."""

import json
import math

import pytest

from groundstation.campaigns.runner import SortieOutcome
from groundstation.campaigns.tune import (
    TuneError,
    main_paired,
    objective_formula,
    paired_campaigns,
    paired_comparison,
    score,
    sign_test_p,
)


def _o(i, outcome, miss, sat=0.0):
    return SortieOutcome(i, {}, {"outcome": outcome, "miss_m": miss}, {"saturated_fraction": sat})


def test_success_mean_ranks_by_hits_then_every_sortie_s_miss():
    n = 5
    # same CEP (median 0.02 m), but one gain set's tail is wider: only the mean sees it
    tight = [_o(i, "HIT", m) for i, m in enumerate([0.01, 0.015, 0.02, 0.025, 0.03])]
    tail = [_o(i, "HIT", m) for i, m in enumerate([0.01, 0.015, 0.02, 0.09, 0.12])]
    assert score(tight, "success-cep", 0).loss == pytest.approx(score(tail, "success-cep", 0).loss)
    a, b = score(tight, "success-mean", 0.0), score(tail, "success-mean", 0.0)
    assert a.mean_miss_m == pytest.approx(0.02) and b.mean_miss_m == pytest.approx(0.051)
    assert a.loss == pytest.approx(0.02 / 1.02 / (2 * n), rel=1e-12) and a.loss < b.loss
    # a lost hit outweighs any mean miss; saturation nudges the mean inside the tie-break
    wide = [_o(i, "HIT", 0.9, sat=1.0) for i in range(n)]
    one_lost = [_o(i, "HIT" if i else "MISS", 0.01) for i in range(n)]
    assert score(wide, "success-mean", 5.0).loss < score(one_lost, "success-mean", 0.0).loss
    c = 0.02 + 0.05 * 0.1
    sat = [_o(i, "HIT", m, sat=0.1) for i, m in enumerate([0.01, 0.015, 0.02, 0.025, 0.03])]
    assert score(sat, "success-mean", 0.05).loss == pytest.approx(c / (c + 1) / (2 * n))
    assert objective_formula("success-mean", 0.05).endswith(
        "c/(c + 1 m)/(2 N), c = mean + 0.05 m x saturated share"
    )


def test_sign_test_matches_the_binomial_by_hand():
    assert sign_test_p(10, 0) == pytest.approx(2 / 1024)
    assert sign_test_p(0, 10) == pytest.approx(2 / 1024)
    assert sign_test_p(8, 2) == pytest.approx(2 * (1 + 10 + 45) / 1024)  # 0.109
    assert sign_test_p(5, 5) == 1.0 and sign_test_p(0, 0) == 1.0


def test_paired_comparison_finds_a_consistent_small_gain_and_not_noise():
    import numpy as np

    rng = np.random.default_rng(7)
    base = 0.04 + 0.013 * np.abs(rng.standard_normal(60))  # CA-like spread, 13 mm
    better = base - 0.004 + 0.002 * rng.standard_normal(60)  # 4 mm closer, paired noise 2 mm
    p = paired_comparison(base, better, [True] * 60, [True] * 60)
    assert p["mean_diff_m"] == pytest.approx(-0.004, abs=0.001)
    assert p["ci95_high_m"] < 0 and p["ci95_low_m"] < p["mean_diff_m"] < p["ci95_high_m"]
    assert p["improved"] > 50 and p["sign_test_p"] < 1e-6
    assert p["hits_won"] == 0 and p["hits_lost"] == 0
    assert paired_comparison(base, better) == {
        k: v for k, v in p.items() if not k.startswith("hits")
    }  # seeded: the same CI every time
    # the same spread, shuffled: no pairing, no real difference -> the CI holds zero
    noise = paired_comparison(base, rng.permutation(base))
    assert noise["ci95_low_m"] < 0 < noise["ci95_high_m"] and noise["sign_test_p"] > 0.05
    # a hit the new set loses is counted whatever the misses
    lost = paired_comparison([0.01, 0.02], [0.01, 0.3], [True, True], [True, False])
    assert lost["hits_lost"] == 1 and lost["hits_won"] == 0 and lost["worsened"] == 1


@pytest.mark.parametrize(
    ("a", "b"),
    [([], []), ([0.1], [0.1, 0.2]), ([0.1, math.nan], [0.1, 0.2])],
)
def test_paired_comparison_refuses_unpaired_or_bad_misses(a, b):
    with pytest.raises(ValueError):
        paired_comparison(a, b)


def _campaign(path, misses, law="png", seed=2):
    sorties = [
        {
            "labels": {"scenario": sc, "law": law, "try": k},
            "seed": seed * 1000 + k,
            "law": law,
            "outcome": "HIT" if m < 0.15 else "MISS",
            "miss_m": m,
        }
        for sc, ms in misses.items()
        for k, m in enumerate(ms)
    ]
    path.mkdir()
    (path / "results.json").write_text(json.dumps({"sorties": sorties}))
    return path


def test_two_campaign_runs_are_paired_per_cell_and_overall(tmp_path, capsys):
    base = _campaign(tmp_path / "a", {"ca": [0.05, 0.04, 0.06, 0.05], "cv": [0.01, 0.02]})
    new = _campaign(tmp_path / "b", {"ca": [0.03, 0.03, 0.05, 0.20], "cv": [0.01, 0.02]})
    cmp = paired_campaigns(base, new / "results.json")
    assert list(cmp) == ["ca", "cv", "all"]
    ca = cmp["ca"]
    assert (ca["n"], ca["improved"], ca["worsened"], ca["hits_lost"]) == (4, 3, 1, 1)
    assert ca["mean_diff_m"] == pytest.approx((-0.02 - 0.01 - 0.01 + 0.15) / 4)
    assert cmp["cv"]["mean_diff_m"] == 0 and cmp["cv"]["improved"] == 0
    assert cmp["all"]["n"] == 6
    assert main_paired([str(base), str(new)]) == 0
    table = capsys.readouterr().out
    assert "| ca | 4 | 0.0500 -> 0.0775 m | +27.5 mm" in table and "| 3 / 1 |" in table
    # other sorties (here another law) are not paired with these
    other = _campaign(tmp_path / "c", {"ca": [0.05] * 4, "cv": [0.01] * 2}, law="pg")
    with pytest.raises(TuneError, match="did not fly the same sorties"):
        paired_campaigns(base, other)
    # two seeds each side pool into one comparison
    base3 = _campaign(tmp_path / "a3", {"ca": [0.05] * 4, "cv": [0.01] * 2}, seed=3)
    new3 = _campaign(tmp_path / "b3", {"ca": [0.04] * 4, "cv": [0.01] * 2}, seed=3)
    pooled = paired_campaigns([base, base3], [new, new3])
    assert pooled["ca"]["n"] == 8 and pooled["ca"]["improved"] == 7
    assert main_paired([f"{base},{base3}", f"{new},{new3}"]) == 0
    assert "| all | 12 |" in capsys.readouterr().out
    with pytest.raises(TuneError, match="given twice"):
        paired_campaigns([base, base], [new, new])
    assert main_paired([str(base), str(tmp_path / "nothing")]) == 2
    assert "not a campaign's results.json" in capsys.readouterr().err
