"""Campaigns: aggregation, determinism across workers, end to end, errors, the paper's claims
at small n."""

import dataclasses
import json
import subprocess
import sys

import pytest
from numpy.testing import assert_allclose

from groundstation.campaigns import CampaignError, LocalPoolRunner, build_jobs
from groundstation.campaigns.aggregate import median_iqr, miss_stats, success_rate
from groundstation.campaigns.definitions import get_campaign, parse_laws, static_targets
from groundstation.campaigns.driver import run_campaign
from groundstation.cli import main
from groundstation.scenario import with_overrides

from .as_written import AS_WRITTEN, set_args  # the conditions these figures were measured in
from .cli_support import run_cli

# the closed-loop figures below are docs/paper.md's perfect-state ones; the state-estimate model's
# own checks and its closed-loop figures are in tests/test_estimate.py
IDEAL = {  # docs/paper.md's perfect-state column, the DKF's random walk for a perfect estimate
    "estimate.enabled": False,
    "gains.t_vel_lag": 0.0,
    "belief.target_accel_noise_m_s2": 1.0,
}


def test_cep_and_spread_of_known_misses():
    s = miss_stats([0.4, 0.1, 0.3, 0.2])
    assert_allclose(s["cep_m"], 0.25)  # median of 0.1, 0.2, 0.3, 0.4
    assert_allclose(s["mean_m"], 0.25)
    assert_allclose(s["p90_m"], 0.37)  # linear interpolation: 0.3 + 0.7 * 0.1
    assert_allclose(s["std_m"], 0.129099, atol=1e-6)
    assert s["n"] == 4 and s["max_m"] == 0.4 and s["min_m"] == 0.1
    assert miss_stats([0.05])["cep_m"] == 0.05
    assert success_rate(["HIT", "MISS", "HIT", "TIMEOUT"]) == 0.5
    assert_allclose(median_iqr([1, 2, 3, 4, 5]), (3.0, 2.0))
    with pytest.raises(ValueError):
        miss_stats([])
    with pytest.raises(ValueError):
        miss_stats([0.1, float("nan")])


def test_static_targets_are_seeded_and_inside_the_view():
    a, b = static_targets(20, seed=3), static_targets(20, seed=3)
    assert a == b and a != static_targets(20, seed=4)
    for x, y, z in a:
        r = (x * x + y * y + (z - 10) ** 2) ** 0.5
        assert 15 <= r <= 35 and z >= 1.0 and y > 0


@pytest.mark.early
def test_results_identical_whatever_the_worker_count():
    jobs = build_jobs("static", n=2, laws=("png", "pg"), seed=5)  # 4 jobs over 2 workers
    one = LocalPoolRunner(1).run(jobs)
    two = LocalPoolRunner(2).run(jobs)
    assert [o.result for o in one] == [o.result for o in two]
    assert [o.trace for o in one] == [o.trace for o in two]
    assert [o.labels for o in one] == [o.labels for o in two]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["campaign", "nope"], "unknown campaign 'nope'; choose one of static, moving"),
        (["campaign", "static", "--laws", "png,zz"], "unknown law(s) zz"),
        (["campaign", "static", "--laws", ""], "--laws needs at least one law"),
        (["campaign", "static", "--n", "0"], "argument --n: must be an integer >= 1"),
        (["campaign", "static", "--set", "gains.k_v=900"], "k_v = 900.0 is outside its range"),
        (["campaign", "static", "--set", "gains.kv=1"], "unknown gain(s): kv"),
        (["campaign", "static", "--set", "camera.noise_px"], "expected SECTION.KEY=VALUE"),
        (["campaign", "static", "--set", "camera.noise_px=-1"], "must not be negative"),
        (["campaign", "static", "--set", "camera.nois_px=0"], "unknown key 'camera.nois_px'"),
        (["campaign", "agility", "--only", "kind"], "expected KEY=VALUE[,VALUE...]"),
        (["campaign", "agility", "--only", "speed=3"], "has no label speed; its labels: kind"),
        (["campaign", "agility", "--only", "value=4"], "keeps no sortie; values there are"),
        (["campaign", "agility", "--only", "kind=turn", "--only", "kind=jink"], "twice"),
    ],
)
def test_bad_campaign_or_law_is_a_clear_error(args, message, tmp_path, capsys):
    # in this process (the installed entry point runs in test_moving_campaign_end_to_end)
    code, _, err = run_cli(main, [*args, "--out", str(tmp_path / "x")], capsys)
    assert code == 2, err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()  # nothing written


def test_parse_laws():
    assert parse_laws("png, ibvs") == ("png", "ibvs")
    with pytest.raises(CampaignError, match="twice"):
        parse_laws("png,png")


@pytest.mark.early
def test_moving_campaign_end_to_end(tmp_path):
    out = tmp_path / "moving"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation",
            "campaign",
            "moving",
            "--n",
            "1",
            "--laws",
            "png,pg",
            "--workers",
            "2",
            "--out",
            str(out),
            "--json",
            "--set",
            "estimate.enabled=false",  # ideal sensors (the model: tests/test_estimate.py)
            *set_args(AS_WRITTEN),  # the camera these figures were measured with
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    d = json.loads(r.stdout)
    cells = d["summary"]["cells"]
    assert set(cells) == {"cv-top-to-bottom", "ca-flanking", "sm-tailgate"}
    for scenario, by_law in cells.items():
        # the paper's claim, at n = 1: the proposed law misses least in every scenario
        assert by_law["png"]["mean_m"] < by_law["pg"]["mean_m"], scenario
        assert by_law["png"]["mean_m"] <= 0.10, scenario
        assert by_law["png"]["paper_m"] is not None
    for name in (
        "results.json",
        "report.md",
        "trajectories_3d.png",
        "normal_accel_velocity.png",
        "image_error_boxplot.png",
        "miss_boxplot.png",
    ):
        assert (out / name).stat().st_size > 1000, name
    results = json.loads((out / "results.json").read_text())
    assert len(results["sorties"]) == 6 and results["meta"]["workers"] == 2
    report = (out / "report.md").read_text()
    assert "(0.71)" in report and "cv-top-to-bottom" in report  # the paper's PG number beside ours


@pytest.mark.early
def test_static_campaign_png_centimetre_cep_beats_ibvs(tmp_path):
    res = run_campaign(
        "static",
        n=8,
        laws=("png", "ibvs"),
        seed=0,
        workers=2,
        out=tmp_path / "s",
        progress=False,
        overrides=IDEAL,
    )
    laws = res["summary"]["laws"]
    assert laws["png"]["cep_m"] <= 0.10  # paper: 0.089 m
    assert laws["png"]["cep_m"] < laws["ibvs"]["cep_m"]
    assert laws["png"]["success_rate"] == 1.0
    for name in ("miss_scatter.png", "targets_image_plane.png", "miss_boxplot.png"):
        assert (tmp_path / "s" / name).exists()


def test_override_reaches_every_sortie_and_the_report(tmp_path):
    # k_v = 1/dt is the proposed law's literal eq. 17 applied to PG: a saturating, limit-cycling
    # pursuit that lands centimetres off instead of millimetres to a centimetre (docs/paper.md,
    # static targets; the airframe's rotor drag, which the velocity loop does not model, costs
    # PG its last millimetres).
    # (with the camera these figures were measured with: a camera 3 cm above the centre of
    # mass, which PG aims at the target, biases its pass by about as much as k_v = 100 does)
    kw = dict(n=2, laws=("pg",), seed=0, workers=1, progress=False)
    ideal = {**AS_WRITTEN, **IDEAL}
    base = run_campaign("static", out=tmp_path / "a", overrides=ideal, **kw)
    literal = run_campaign(
        "static", out=tmp_path / "b", overrides={**ideal, "gains.k_v": 100}, **kw
    )
    assert literal["meta"]["overrides"] == {**ideal, "gains.k_v": 100}
    assert base["meta"]["overrides"] == ideal
    assert "--set gains.k_v=100" in literal["meta"]["command"]
    report = (tmp_path / "b" / "report.md").read_text()
    assert "gains.k_v = 100" in report and "State estimate: off" in report
    miss = {k: r["summary"]["laws"]["pg"]["mean_m"] for k, r in (("a", base), ("b", literal))}
    assert miss["a"] < 0.03 and miss["b"] > 3 * miss["a"], miss
    assert literal["outcomes"][0].result["max_normal_accel_m_s2"] > 4.5  # saturates (a_max 5)


@pytest.mark.early
def test_wind_campaign_png_always_hits_in_still_air(tmp_path):
    # the claim's four still-air tries, the campaign's own sorties (its jobs, seeds and summary)
    jobs = [
        dataclasses.replace(j, scenario=with_overrides(j.scenario, IDEAL))
        for j in build_jobs("wind", n=4, laws=("png",), seed=0)
        if dict(j.labels)["wind_m_s"] == 0
    ]
    outcomes = LocalPoolRunner(1).run(jobs)
    # every still-air try hits the balloon; a sortie's outcome also counts its recovery: the
    # brake comes when the track goes stale, 0.5 s after the balloon left the image 1 m above
    # the floor, and one of the four (seed 0, descending fastest) reaches the floor: CRASHED
    still = [o.result for o in outcomes]
    assert len(still) == 4 and all(r["miss_m"] <= r["hit_radius_m"] for r in still), still
    assert get_campaign("wind").summarize(outcomes)["cells"]["0"]["png"]["success_rate"] >= 0.75
    # the campaign end to end, one try per wind speed: every cell and its figure
    res = run_campaign(
        "wind",
        n=1,
        laws=("png",),
        seed=0,
        workers=1,
        out=tmp_path / "w",
        progress=False,
        overrides=IDEAL,
    )
    cells = res["summary"]["cells"]
    assert set(cells) == {"0", "2", "4", "6"}
    assert all(0.0 <= c["png"]["success_rate"] <= 1.0 for c in cells.values())
    flown = [o.result for o in res["outcomes"] if dict(o.labels)["wind_m_s"] == 0]
    assert flown == still[:1]  # the same still-air sortie, seed 0
    assert (tmp_path / "w" / "success_rate.png").exists()


@pytest.mark.early
def test_outdoor_campaign_reports_speed(tmp_path):
    res = run_campaign(
        "outdoor",
        n=1,
        laws=("png",),
        workers=1,
        out=tmp_path / "o",
        progress=False,
        overrides=IDEAL,
    )
    for scenario, by_law in res["summary"]["cells"].items():
        assert by_law["png"]["success_rate"] == 1.0, scenario
        # the speed ramp gains k_a net of drag: the escaping target is chased past 8 m/s
        assert 4.0 <= by_law["png"]["terminal_speed_mean_m_s"] <= 9.0, scenario
