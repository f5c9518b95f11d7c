"""Campaign ``agility`` (docs/agility.md): success and miss against the target's agility, for
each law. Two sweeps from a vehicle flying forward at 2 m/s at (0, 0, 10) m:

- turn: a target 20-30 m ahead (azimuth +-15 deg, elevation +-5 deg from the nose) flying
  at 5 m/s on a heading drawn uniformly, turning to a drawn side at each lateral
  acceleration of :data:`TURN_ACCELS_M_S2` (a coordinated turn of radius 25 m^2/s^2 / a);
- jink: a target hovering at the same places that darts sideways at 2.5 m/s (8 m/s^2),
  across the line of sight to a side drawn per sortie, when the vehicle comes within each
  range of :data:`JINK_RANGES_M`.

Try k of a cell flies the same target draw and the same seed for every law (paired). The
summary sets each acceleration against the available lateral acceleration of the airframe the
vehicle believes (onboard/control/apn.py).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from onboard.control.apn import available_lateral_accel_m_s2
from onboard.gains import Gains

from ..scenario import load_scenario, with_changes
from .aggregate import miss_stats, success_rate
from .runner import SortieJob, SortieOutcome

TURN_ACCELS_M_S2 = (0.5, 1.0, 2.0, 3.0, 5.0, 7.5, 10.0)
JINK_RANGES_M = (3.0, 5.0, 8.0, 10.0, 15.0)
TURN_SPEED_M_S = 5.0
JINK_SPEED_M_S, JINK_ACCEL_M_S2 = 2.5, 8.0
START_M = (0.0, 0.0, 10.0)
RANGE_M, AZIMUTH_DEG, ELEVATION_DEG = (20.0, 30.0), 15.0, 5.0
DURATION_S = 15.0


def _place(rng: np.random.Generator) -> tuple[float, float, float]:
    """A start 20-30 m from :data:`START_M` within +-15 deg azimuth and +-5 deg elevation of
    the nose (+y)."""
    r = float(rng.uniform(*RANGE_M))
    az = math.radians(float(rng.uniform(-AZIMUTH_DEG, AZIMUTH_DEG)))
    el = math.radians(float(rng.uniform(-ELEVATION_DEG, ELEVATION_DEG)))
    x0, y0, z0 = START_M
    return (
        x0 + r * math.cos(el) * math.sin(az),
        y0 + r * math.cos(el) * math.cos(az),
        z0 + r * math.sin(el),
    )


def build(n: int, laws: tuple[str, ...], camera: str, seed: int) -> list[SortieJob]:
    """The jobs of both sweeps (module docstring): every cell x n tries x law."""
    base = load_scenario("static-ahead-20m")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xA617]))
    jobs: list[SortieJob] = []
    cells = [("turn", a) for a in TURN_ACCELS_M_S2] + [("jink", r) for r in JINK_RANGES_M]
    for kind, value in cells:
        for k in range(n):
            pos = _place(rng)
            if kind == "turn":
                heading = float(rng.uniform(0.0, 2.0 * math.pi))
                side = 1.0 if rng.uniform() < 0.5 else -1.0
                target = dataclasses.replace(
                    base.target,
                    motion="turn",
                    position_m=pos,
                    velocity_m_s=(
                        TURN_SPEED_M_S * math.cos(heading),
                        TURN_SPEED_M_S * math.sin(heading),
                        0.0,
                    ),
                    lateral_accel_m_s2=side * value,
                )
            else:
                target = dataclasses.replace(
                    base.target,
                    motion="jink",
                    position_m=pos,
                    trigger_range_m=value,
                    jink_speed_m_s=JINK_SPEED_M_S,
                    jink_accel_m_s2=JINK_ACCEL_M_S2,
                )
            sc = with_changes(base, name=f"agility-{kind}-{value:g}", target=target)
            sc = dataclasses.replace(sc, duration_s=DURATION_S)
            for law in laws:
                labels = (("kind", kind), ("value", value), ("law", law), ("try", k))
                jobs.append(SortieJob(len(jobs), sc, law, seed * 1000 + k, camera, labels))
    return jobs


def wilson_interval(hits: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95 % Wilson score interval of a success rate of ``hits`` in ``n``."""
    if n == 0:
        return 0.0, 1.0
    p = hits / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(centre - half, 0.0), min(centre + half, 1.0)


def available_accel_m_s2() -> float:
    """The believed airframe's available lateral acceleration with the default gains and
    hover thrust (thrust-to-weight 3): the augmented law's command limit."""
    g = Gains()
    return available_lateral_accel_m_s2(1.0 / 3.0, g.tilt_max, g.a_z_margin)


def summarize(outcomes: list[SortieOutcome]) -> dict[str, Any]:
    """cells[kind][value][law]: success rate with its 95 % interval, miss statistics and the
    outcomes; for turns the acceleration's share of the available one."""
    avail = available_accel_m_s2()
    groups: dict[tuple, list[SortieOutcome]] = {}
    for o in outcomes:
        key = (o.labels["kind"], o.labels["value"], o.labels["law"])
        groups.setdefault(key, []).append(o)
    cells: dict[str, dict[str, dict[str, Any]]] = {}
    for (kind, value, law), outs in groups.items():
        results = [o.result["outcome"] for o in outs]
        hits = sum(r == "HIT" for r in results)
        counts: dict[str, int] = {}
        for r in results:
            counts[r] = counts.get(r, 0) + 1
        cell = {
            **miss_stats([o.result["miss_m"] for o in outs]),
            "success_rate": success_rate(results),
            "success_95": wilson_interval(hits, len(outs)),
            "outcomes": dict(sorted(counts.items())),
        }
        if kind == "turn":
            cell["accel_ratio"] = value / avail
        cells.setdefault(kind, {}).setdefault(f"{value:g}", {})[law] = cell
    return {"cells": cells, "available_accel_m_s2": avail}


def markdown(summary: dict[str, Any]) -> str:
    """The report's tables: success (95 % interval) and mean miss per cell and law."""
    from .plots import LAW_NAMES

    avail = summary["available_accel_m_s2"]
    lines = [
        f"Available lateral acceleration of the believed airframe: {avail:.2f} m/s^2 "
        "(thrust-to-weight 3, tilt limit 45 deg; the augmented law's command limit; PNG, PG "
        "and IBVS keep a_max).",
    ]
    titles = {
        "turn": "Turning target: lateral acceleration (m/s^2)",
        "jink": "Jinking target (2.5 m/s sideways): range at the jink (m)",
    }
    for kind, by_value in summary["cells"].items():
        laws = list(next(iter(by_value.values())))
        lines += ["", f"### {titles[kind]}", ""]
        head = "| value | " + " | ".join(LAW_NAMES.get(x, x) for x in laws) + " |"
        lines += [head, "|---|" + "---|" * len(laws)]
        for value, by_law in sorted(by_value.items(), key=lambda kv: float(kv[0])):
            row = []
            for law in laws:
                c = by_law[law]
                lo, hi = c["success_95"]
                row.append(
                    f"{100 * c['success_rate']:.0f} % ({100 * lo:.0f}-{100 * hi:.0f}), "
                    f"{c['mean_m']:.2f} m"
                )
            label = value if kind == "jink" else f"{value} ({float(value) / avail:.2f} of avail.)"
            lines.append(f"| {label} | " + " | ".join(row) + " |")
    lines += ["", "Each cell: HIT rate (95 % Wilson interval), mean miss."]
    return "\n".join(lines)


def plots(summary: dict[str, Any], out: Path) -> list[str]:
    """agility.png: success and mean miss against the turn's lateral acceleration and the
    jink's range, one line per law, the available acceleration marked."""
    from .plots import LAW_COLOURS, LAW_NAMES, _savefig, plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7), squeeze=False)
    avail = summary["available_accel_m_s2"]
    for col, kind in enumerate(("turn", "jink")):
        by_value = summary["cells"].get(kind, {})
        if not by_value:
            continue
        values = sorted(by_value, key=float)
        x = [float(v) for v in values]
        for law in by_value[values[0]]:
            cells = [by_value[v][law] for v in values]
            rate = [100 * c["success_rate"] for c in cells]
            lo = [100 * c["success_95"][0] for c in cells]
            hi = [100 * c["success_95"][1] for c in cells]
            colour = LAW_COLOURS.get(law, "k")
            axes[0][col].plot(x, rate, "o-", color=colour, label=LAW_NAMES.get(law, law))
            axes[0][col].fill_between(x, lo, hi, color=colour, alpha=0.12)
            axes[1][col].plot(x, [c["mean_m"] for c in cells], "o-", color=colour)
        axes[1][col].set_yscale("log")
        if kind == "turn":
            for ax in (axes[0][col], axes[1][col]):
                ax.axvline(avail, color="k", ls="--", lw=0.8)
                ax.axvline(avail / 2, color="k", ls=":", lw=0.8)
            axes[1][col].set_xlabel(
                "target lateral acceleration (m/s²); dashed: available, dotted: half"
            )
        else:
            axes[1][col].set_xlabel("range when the target jinks (m)")
        axes[0][col].set_ylabel("HIT (%)")
        axes[0][col].set_ylim(-3, 103)
        axes[1][col].set_ylabel("mean miss (m)")
    axes[0][0].legend(fontsize=8)
    names: list[str] = []
    _savefig(fig, out, "agility.png", names)
    return names
