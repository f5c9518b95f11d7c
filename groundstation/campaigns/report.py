"""Campaign output: ``results.json`` (every sortie and the aggregates), ``report.md`` (the
tables, the paper's numbers beside ours) and the PNG plots (drawn by :mod:`.plots`)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import numpy as np

from onboard.enums import GuidanceLaw

from . import agility
from .plots import (
    LAW_COLOURS,
    LAW_NAMES,
    _envelope_plots,
    _laws_of,
    _moving_plots,
    _outdoor_plots,
    _range_plots,
    _static_plots,
    _wind_plots,
    envelope_grid,
)
from .runner import SortieOutcome

__all__ = ["LAW_COLOURS", "LAW_NAMES", "tables_markdown", "write_report"]


def _fmt(x: Any, digits: int = 3) -> str:
    if x is None:
        return "—"
    if isinstance(x, float) and not math.isfinite(x):
        return "—"
    return f"{x:.{digits}f}"


def _md_static(summary, outcomes) -> str:
    lines = [
        "| law | CEP (median) | mean | 90th pct | max | HIT rate | terminal speed | paper CEP |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for law, s in summary["laws"].items():
        lines.append(
            f"| {LAW_NAMES.get(law, law)} | {_fmt(s['cep_m'])} m | {_fmt(s['mean_m'])} m | "
            f"{_fmt(s['p90_m'])} m | {_fmt(s['max_m'])} m | {100 * s['success_rate']:.0f} % | "
            f"{_fmt(s['terminal_speed_mean_m_s'], 2)} m/s | {_fmt(s['paper_cep_m'])} |"
        )
    sides = [
        (law, side, s[side])
        for law, s in summary["laws"].items()
        for side in ("believed_smaller", "believed_larger")
        if side in s
    ]
    if sides:
        lines += [
            "",
            "| law | believed size | n | HIT rate | CEP | max |",
            "|---|---|---|---|---|---|",
        ]
        for law, side, c in sides:
            lines.append(
                f"| {LAW_NAMES.get(law, law)} | {side.split('_')[1]} than true | {c['n']} | "
                f"{100 * c['success_rate']:.0f} % | {_fmt(c['cep_m'])} m | {_fmt(c['max_m'])} m |"
            )
    lines.append(f"\nPaper: {summary['paper_note']}.\n\nEvery miss (m):\n")
    laws = _laws_of(outcomes)
    lines.append("| target | position (m) | " + " | ".join(laws) + " |")
    lines.append("|---|---|" + "---|" * len(laws))
    targets = sorted({o.labels["target"] for o in outcomes})
    for t in targets:
        row = [o for o in outcomes if o.labels["target"] == t]
        pos = row[0].trace["target_pos_m"][0] if row[0].trace else None
        pos_s = "—" if pos is None else "(" + ", ".join(f"{c:.1f}" for c in pos) + ")"
        misses = {o.labels["law"]: o.result for o in row}
        cells = [
            f"{misses[law]['miss_m']:.3f}"
            + ("" if misses[law]["outcome"] == "HIT" else f" {misses[law]['outcome']}")
            for law in laws
        ]
        lines.append(f"| {t} | {pos_s} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _md_moving(summary) -> str:
    cells = summary["cells"]
    laws = list(next(iter(cells.values())).keys())
    head = "| miss, mean ± std (paper) | " + " | ".join(LAW_NAMES.get(x, x) for x in laws) + " |"
    lines = [head, "|---|" + "---|" * len(laws)]
    for sc, by_law in cells.items():
        row = []
        best = min(by_law, key=lambda law: by_law[law]["mean_m"])
        for law in laws:
            c = by_law[law]
            txt = f"{c['mean_m']:.3f} ± {c['std_m']:.3f} m ({_fmt(c['paper_m'], 2)})"
            row.append(f"**{txt}**" if law == best else txt)
        lines.append(f"| {sc} | " + " | ".join(row) + " |")
    lines += [
        "",
        "| scenario, law | HIT rate | outcomes | terminal speed | mean of max normal accel | "
        "median (IQR) e_x/f | median (IQR) e_y/f |",
        "|---|---|---|---|---|---|---|",
    ]
    for sc, by_law in cells.items():
        for law, c in by_law.items():
            (mx, ix), (my, iy) = c["e_x_median_iqr"], c["e_y_median_iqr"]
            lines.append(
                f"| {sc}, {law} | {100 * c['success_rate']:.0f} % | {', '.join(c['outcomes'])} | "
                f"{c['terminal_speed_mean_m_s']:.2f} m/s | "
                f"{c['max_normal_accel_mean_m_s2']:.2f} m/s² | {mx:.3f} ({ix:.3f}) | "
                f"{my:.3f} ({iy:.3f}) |"
            )
    return "\n".join(lines)


def _md_wind(summary) -> str:
    cells = summary["cells"]
    laws = list(next(iter(cells.values())).keys())
    lines = [
        "| wind | "
        + " | ".join(f"{LAW_NAMES.get(x, x)} HIT rate (terminal speed)" for x in laws)
        + " | paper (proposed) |",
        "|---|" + "---|" * (len(laws) + 1),
    ]
    for w, by_law in cells.items():
        rates = [
            f"{100 * by_law[x]['success_rate']:.0f} % ({by_law[x]['tries']}; "
            f"{by_law[x]['terminal_speed_mean_m_s']:.1f} m/s)"
            for x in laws
        ]
        paper = summary["paper"][w]["success"] * 100
        lines.append(f"| {w} m/s | " + " | ".join(rates) + f" | {paper:.0f} % (5) |")
    law = GuidanceLaw.PNG.value if GuidanceLaw.PNG.value in laws else laws[0]  # the paper's law
    lines += [
        "",
        f"Image plane, {LAW_NAMES.get(law, law)}: normalised (u, v), ours | paper",
        "",
        "| wind | median (u, v) | IQR (u, v) | paper median | paper IQR |",
        "|---|---|---|---|---|",
    ]
    for w, by_law in cells.items():
        c, p = by_law[law], summary["paper"][w]
        lines.append(
            f"| {w} m/s | ({c['median_uv'][0]:.3f}, {c['median_uv'][1]:.3f}) | "
            f"({c['iqr_uv'][0]:.3f}, {c['iqr_uv'][1]:.3f}) | "
            f"({p['median_uv'][0]:.3f}, {p['median_uv'][1]:.3f}) | "
            f"({p['iqr_uv'][0]:.3f}, {p['iqr_uv'][1]:.3f}) |"
        )
    return "\n".join(lines)


def _md_outdoor(summary) -> str:
    lines = [
        "| scenario | law | HIT rate | CEP | miss mean | terminal speed | time | paper |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for sc, by_law in summary["cells"].items():
        for law, c in by_law.items():
            lines.append(
                f"| {sc} | {LAW_NAMES.get(law, law)} | {100 * c['success_rate']:.0f} % | "
                f"{c['cep_m']:.3f} m | {c['mean_m']:.3f} m | "
                f"{c['terminal_speed_mean_m_s']:.2f} m/s | "
                f"{c['intercept_time_mean_s']:.2f} s | {c['paper'] or ''} |"
            )
    return "\n".join(lines)


def _md_envelope(summary) -> str:
    lines = []
    for law in summary["cells"]:
        ok, rows, cols = envelope_grid(summary, law, "success_rate")
        cep, _, _ = envelope_grid(summary, law, "cep_m")
        lines += [
            f"{LAW_NAMES.get(law, law)}: HIT rate / CEP (m) by elevation (rows) and azimuth "
            "(columns) from the nose, degrees",
            "",
            "| elevation | " + " | ".join(f"az {c}" for c in cols) + " |",
            "|---|" + "---|" * len(cols),
        ]
        for i in reversed(range(len(rows))):
            cells = [
                "—" if not math.isfinite(ok[i, j]) else f"{100 * ok[i, j]:.0f} % / {cep[i, j]:.3f}"
                for j in range(len(cols))
            ]
            lines.append(f"| {rows[i]} | " + " | ".join(cells) + " |")
        good = summary["good_elevations_deg"][law]
        lines += [
            "",
            f"Elevations where every azimuth cell meets {summary['criterion']}: "
            + (", ".join(f"{e:g}" for e in sorted(good)) or "none")
            + "",
            "",
        ]
    return "\n".join(lines)


def _md_range(summary) -> str:
    lines = [
        "| range | law | HIT rate | CEP | acquired | acquisition range (median) | "
        "ZEM at acquisition (median) | ZEM < 1 m from (median, after acquisition) | "
        "range then (median) | ... for at least (before the end) | settled |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r, by_law in summary["cells"].items():
        for law, c in by_law.items():
            lines.append(
                f"| {r} m | {LAW_NAMES.get(law, law)} | {100 * c['success_rate']:.0f} % | "
                f"{_fmt(c['cep_m'])} m | {100 * c['acquired_rate']:.0f} % | "
                f"{_fmt(c['acq_range_median_m'], 1)} m | {_fmt(c['zem_acq_median_m'], 2)} m | "
                f"{_fmt(c['zem_settle_median_s'], 2)} s | "
                f"{_fmt(c.get('zem_settle_range_median_m'), 1)} m | "
                f"{_fmt(c['zem_lead_min_s'], 2)} s | "
                f"{100 * c['zem_settled_rate']:.0f} % |"
            )
    lines.append(
        "\nZEM (zero-effort miss): the miss if neither vehicle nor target accelerated from then "
        "on, from the true states. 'Settled' counts sorties whose ZEM, from some time after "
        "acquisition, stays under 1 m to the end; the column before is the shortest such stretch."
    )
    return "\n".join(lines)


def tables_markdown(name: str, summary: dict[str, Any], outcomes: list[SortieOutcome]) -> str:
    if name in ("static", "size"):
        return _md_static(summary, outcomes)
    if name == "moving":
        return _md_moving(summary)
    if name == "wind":
        return _md_wind(summary)
    if name == "envelope":
        return _md_envelope(summary)
    if name == "range":
        return _md_range(summary)
    if name == "agility":
        return agility.markdown(summary)
    return _md_outdoor(summary)


def _estimate_note(estimate: dict | None) -> str:
    """One sentence naming the state-estimate model the sorties flew with."""
    if not estimate:
        return ""
    if not estimate.get("enabled", True) or estimate.get("profile") == "ideal":
        return "State estimate: off (ideal sensors, analysis only: the loop saw the truth). "
    from ..scenario import EstimateSpec

    changed = {
        k: v
        for k, v in estimate.items()
        if getattr(EstimateSpec(), k, v) != v and k not in ("enabled", "profile")
    }
    extra = "".join(f", {k} = {v}" for k, v in changed.items())
    profile = estimate.get("profile", EstimateSpec().profile)
    return f"State estimate: on (error profile {profile}, docs/realism.md{extra}). "


def write_report(
    out: Path,
    name: str,
    meta: dict[str, Any],
    summary: dict[str, Any],
    outcomes: list[SortieOutcome],
) -> list[str]:
    """Write results.json, report.md and the plots into ``out``; return the file names."""
    out.mkdir(parents=True, exist_ok=True)
    results = {
        "meta": meta,
        "summary": summary,
        "sorties": [{"labels": o.labels, **o.result} for o in outcomes],
        "traces": [o.trace for o in outcomes],
    }
    (out / "results.json").write_text(json.dumps(results, indent=1, default=_json_default))
    plots = {
        "static": lambda: _static_plots(outcomes, out),
        "moving": lambda: _moving_plots(outcomes, out),
        "wind": lambda: _wind_plots(outcomes, summary, out),
        "outdoor": lambda: _outdoor_plots(outcomes, out),
        "drag": lambda: _outdoor_plots(outcomes, out),
        "heldout": lambda: _outdoor_plots(outcomes, out),
        "size": lambda: _static_plots(outcomes, out),
        "envelope": lambda: _envelope_plots(summary, out),
        "range": lambda: _range_plots(outcomes, summary, out),
        "agility": lambda: agility.plots(summary, out),
    }[name]()
    md = [
        f"# Campaign `{name}`",
        "",
        f"Command: `{meta['command']}`  ",
        f"{meta['sorties']} sorties, camera {meta['camera']}, laws {', '.join(meta['laws'])}, "
        f"seed {meta['seed']}, n = {meta['n']} {meta['what_n_counts']}"
        + "".join(f", {k} = {v}" for k, v in meta.get("overrides", {}).items())
        + ". "
        + _estimate_note(meta.get("estimate"))
        + "Regenerate with the command above; the tables come from `results.json`.",
        "",
        tables_markdown(name, summary, outcomes),
        "",
        "## Plots",
        "",
        *[f"![{p}]({p})" for p in plots],
        "",
    ]
    (out / "report.md").write_text("\n".join(md))
    return ["results.json", "report.md", *plots]


def _json_default(x: Any) -> Any:
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, tuple):
        return list(x)
    raise TypeError(f"not JSON serialisable: {type(x)}")
