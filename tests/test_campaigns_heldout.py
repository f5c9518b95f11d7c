"""The held-out campaign: scenarios nobody tuned on (groundstation/scenarios/heldout/), flown
like the paper's cases and set beside the paper's figure for their kind of motion."""

import re
from pathlib import Path

from groundstation.campaigns.definitions import (
    CAMPAIGNS,
    PAPER_BY_MOTION,
    get_campaign,
    heldout_scenarios,
)
from groundstation.campaigns.report import tables_markdown, write_report
from groundstation.campaigns.runner import SortieOutcome
from groundstation.cli import _build_parser as build_parser
from groundstation.scenario import load_scenario, shipped_scenarios

ROOT = Path(__file__).resolve().parents[1]


def test_heldout_scenarios_are_apart_from_the_shipped_ones_and_cover_every_kind():
    held = heldout_scenarios()
    assert len(held) >= 8
    shipped = {p.stem for p in shipped_scenarios()}
    assert not set(held) & shipped  # not offered where gains are tuned by hand
    motions = [load_scenario(path).target.motion for path in held.values()]
    assert set(motions) == set(PAPER_BY_MOTION)  # static, CV, CA and SM, each at least twice
    assert all(motions.count(m) >= 2 for m in PAPER_BY_MOTION)
    for name, path in held.items():
        assert load_scenario(path).name == name


def test_no_other_test_or_tuning_names_a_heldout_scenario():
    """What keeps them held out: no other test, default or study flies them."""
    names = re.compile("|".join(heldout_scenarios()))
    own = Path(__file__).resolve()
    found = [
        str(p.relative_to(ROOT))
        for d in ("tests", "groundstation", "onboard", "web")
        for p in (ROOT / d).rglob("*")
        if p.suffix in (".py", ".js", ".html", ".toml", ".json")
        and p.resolve() != own
        and "heldout" not in p.parts
        and names.search(p.read_text(encoding="utf-8", errors="replace"))
    ]
    assert not found, found


def test_heldout_campaign_flies_each_scenario_n_times_and_reports_the_papers_figure(tmp_path):
    jobs = get_campaign("heldout").build(3, ("png", "apn"), "projected", 2)
    held = heldout_scenarios()
    assert len(jobs) == len(held) * 2 * 3
    assert {dict(j.labels)["scenario"] for j in jobs} == set(held)
    assert sorted({j.seed for j in jobs}) == [2000, 2001, 2002]  # try k: the same seed per cell
    outcomes = [
        SortieOutcome(
            j.index,
            dict(j.labels),
            {
                "outcome": "HIT",
                "miss_m": 0.01 * (1 + dict(j.labels)["try"]),
                "terminal_speed_m_s": 8.0,
                "intercept_time_s": 5.0,
            },
        )
        for j in jobs
    ]
    summary = get_campaign("heldout").summarize(outcomes)
    cell = summary["cells"]["heldout-ca-crossing"]
    assert cell["png"]["paper"] == "paper CA mean 0.45 m" and cell["apn"]["paper"] is None
    assert cell["png"]["cep_m"] == 0.02 and abs(cell["png"]["mean_m"] - 0.02) < 1e-12
    table = tables_markdown("heldout", summary, outcomes)
    assert "| heldout-sm-vertical | PNG (proposed) | 100 % | 0.020 m | 0.020 m |" in table
    meta = {"command": "c", "sorties": len(jobs), "camera": "projected", "laws": ["png", "apn"]}
    meta |= {"seed": 2, "n": 3, "what_n_counts": "seeds per scenario"}
    files = write_report(tmp_path, "heldout", meta, summary, outcomes)  # eight scenarios' panels
    assert "report.md" in files and (tmp_path / "trajectories_3d.png").stat().st_size > 0


def test_the_campaign_command_names_every_campaign():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    help_text = next(a for a in sub.choices["campaign"]._actions if a.dest == "name").help
    assert help_text.split(" | ") == list(CAMPAIGNS)
