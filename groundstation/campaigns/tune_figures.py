"""What a study's sorties scored (the objectives) and the study's report: figures in
Markdown, every trial in results.json, Optuna's plots as PNG."""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .aggregate import success_rate
from .paired import paired_markdown
from .runner import SortieOutcome
from .tune_options import OBJECTIVE_HELP, TuneError


@dataclass
class Figures:
    """What a set of sorties scored: HIT rate, CEP (median miss, m), mean miss (m), mean
    share of control ticks saturated, and the objective's loss (lower is better)."""

    n: int
    success_rate: float
    cep_m: float
    mean_miss_m: float
    saturated: float
    loss: float

    def to_json_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)


def score(outcomes: Sequence[SortieOutcome], objective: str, saturation_penalty: float) -> Figures:
    """The objective (minimised). The saturation penalty adds ``penalty x`` the mean share of
    saturated ticks (in metres for the miss objectives). ``success-cep`` is lexicographic: its
    tie-break c/(c + 1 m)/(2 N), c = CEP + penalty x saturated share, stays below half of one
    sortie's share of the HIT rate whatever the penalty, so no CEP gain buys back a lost hit,
    and when every sortie hits the CEP is not drowned by a penalty outside the tie-break.
    ``success-mean`` is the same with the mean miss in place of the CEP: every sortie's miss
    counts, where a median of N moves with whichever sortie sits in the middle."""
    n = len(outcomes)
    if n == 0:
        raise ValueError("no sorties to score")
    misses = sorted(float(o.result["miss_m"]) for o in outcomes)
    success = success_rate([o.result["outcome"] for o in outcomes])
    cep = float(misses[n // 2] if n % 2 else 0.5 * (misses[n // 2 - 1] + misses[n // 2]))
    sat = sum(float((o.trace or {}).get("saturated_fraction", 0.0)) for o in outcomes) / n
    cost = saturation_penalty * sat
    mean = sum(misses) / n
    if objective in ("success-cep", "success-mean"):
        c = (cep if objective == "success-cep" else mean) + cost
        loss = (1.0 - success) + c / (c + 1.0) / (2 * n)
    elif objective == "cep":
        loss = cep + cost
    elif objective == "success":
        loss = (1.0 - success) + cost
    else:
        raise TuneError(f"unknown objective {objective!r}")
    return Figures(n, success, cep, mean, sat, loss)


def objective_formula(objective: str, saturation_penalty: float) -> str:
    """The objective in words and symbols, with the penalty where :func:`score` adds it."""
    text = OBJECTIVE_HELP[objective]
    if not saturation_penalty:
        return text
    if objective in ("success-cep", "success-mean"):
        stat = "CEP" if objective == "success-cep" else "mean"
        return text.replace(f"{stat}/({stat} + 1 m)", "c/(c + 1 m)") + (
            f", c = {stat} + {saturation_penalty:g} m x saturated share"
        )
    return text + f" + {saturation_penalty:g}{' m' if objective == 'cep' else ''} x saturated share"


def _fig_row(label: str, f: dict[str, float]) -> str:
    return (
        f"| {label} | {100 * f['success_rate']:.0f} % | {f['cep_m']:.3f} m | "
        f"{f['mean_miss_m']:.3f} m | {100 * f['saturated']:.1f} % | {f['loss']:.4f} |"
    )


def figures_markdown(meta: dict[str, Any], figures: dict[str, Any]) -> str:
    d = meta["definition"]
    lines = [
        f"Study `{meta['study']}`: {meta['trials_complete']} complete trials, "
        f"{meta['train_sorties_per_trial']} training sorties each (seed {d['seed']}), "
        f"{meta['held_out_sorties']} held-out sorties (seed {d['holdout_seed']}); "
        f"objective `{d['objective']}`: {meta['objective_formula']}.",
        "",
        "| gains | HIT rate | CEP | mean miss | saturated | loss |",
        "|---|---|---|---|---|---|",
        _fig_row("defaults, train", figures["defaults"]["train"]),
        _fig_row(f"best (trial {meta['best_trial']}), train", figures["best"]["train"]),
        _fig_row("defaults, held-out", figures["defaults"]["held_out"]),
        _fig_row(f"best (trial {meta['best_trial']}), held-out", figures["best"]["held_out"]),
        "",
        paired_markdown(figures["paired_held_out"]) if "paired_held_out" in figures else "",
        "",
        "| gain | default | best | searched |",
        "|---|---|---|---|",
    ]
    for r in d["space"]:
        name = r["name"]
        lines.append(
            f"| {name} | {meta['default_gains'][name]:g} | {meta['best_gains'][name]:.4g} | "
            f"[{r['low']:g}, {r['high']:g}]{' log' if r['log'] else ''} |"
        )
    lines += ["", f"Saved as gain set `{meta['gainset']}` ({meta['gainset_file']})."]
    return "\n".join(lines)


def write_tune_report(
    out: Path, study: Any, meta: dict[str, Any], figures: dict[str, Any]
) -> list[str]:
    """report.md, results.json (every trial) and Optuna's plots as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import optuna
    from optuna.visualization import matplotlib as ovm

    out.mkdir(parents=True, exist_ok=True)
    complete = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    # The success-cep loss spans decades (a lost hit costs 1/N, a centimetre of CEP 1e-4):
    # on a linear axis every trial that hits looks the same, so plot log10(loss) when it can.
    log = bool(complete) and all(t.value is not None and t.value > 0 for t in complete)
    kw: dict[str, Any] = (
        {"target": lambda t: math.log10(t.value), "target_name": "log10(loss)"} if log else {}
    )
    plots = {
        "optimization_history.png": lambda: ovm.plot_optimization_history(study),
        "param_importances.png": lambda: ovm.plot_param_importances(study, **kw),
        "parallel_coordinate.png": lambda: ovm.plot_parallel_coordinate(study, **kw),
    }
    files, skipped = [], []
    for name, plot in plots.items():
        if name == "param_importances.png" and (len(complete) < 2 or len(meta["best_gains"]) < 2):
            skipped.append(f"{name} (needs 2 or more trials and gains)")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ax = plot()
        fig = ax.figure if hasattr(ax, "figure") else ax.flat[0].figure
        if log and name == "optimization_history.png":
            ax.set_yscale("log")  # keeps Optuna's best-so-far line, which a target would drop
            ax.set_ylabel("loss (log scale)")
        fig.set_size_inches(13 if name.startswith("parallel") else 9, 6)
        fig.tight_layout()
        fig.savefig(out / name, dpi=100)
        plt.close(fig)
        files.append(name)
    trials = [
        {
            "number": t.number,
            "state": t.state.name,
            "loss": t.value,
            "params": t.params,
            "figures": {k: t.user_attrs.get(k) for k in Figures.__dataclass_fields__},
            "defaults": bool(t.user_attrs.get("defaults")),
        }
        for t in study.trials
    ]
    (out / "results.json").write_text(
        json.dumps({"meta": meta, "figures": figures, "trials": trials}, indent=1),
        encoding="utf-8",
    )
    md = [
        f"# Gain tuning: {meta['study']}",
        "",
        f"`{meta['command']}`" if meta["command"] else "",
        "",
        figures_markdown(meta, figures),
        "",
        f"Storage `{meta['storage']}`; this run: {meta['trials_run_now']} trials in "
        f"{meta['study_wall_s']:.1f} s wall, held-out check {meta['held_out_check_wall_s']:.1f} s "
        f"({meta['backend']}, {meta['workers']} workers).",
        "",
    ]
    md += [f"![{f}]({f})" for f in files]
    if skipped:
        md += ["", "Not drawn: " + ", ".join(skipped)]
    (out / "report.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    return ["report.md", "results.json", *files]
