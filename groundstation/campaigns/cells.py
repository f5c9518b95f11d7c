"""What the campaigns share: grouping outcomes by their labels, a grid of scenario cells x laws
x seeds, the terminal speed of a cell."""

from __future__ import annotations

import numpy as np

from ..scenario import load_scenario
from .runner import SortieJob, SortieOutcome


def group(outcomes, *keys):
    groups: dict[tuple, list[SortieOutcome]] = {}
    for o in outcomes:
        groups.setdefault(tuple(o.labels[k] for k in keys), []).append(o)
    return groups


def build_grid(cells, n, laws, camera, seed):
    """Jobs for every (label, scenario name) cell x law x n seeds; the seed of try k is the
    same for every cell and law, so laws are compared on the same noise."""
    jobs = []
    for key, value, name in cells:
        sc = load_scenario(name)
        for law in laws:
            for k in range(n):
                labels = ((key, value), ("law", law), ("try", k))
                jobs.append(SortieJob(len(jobs), sc, law, seed * 1000 + k, camera, labels))
    return jobs


def terminal_speed(outs) -> float:
    """The vehicle's mean speed at the closest approach (m/s) over a cell's sorties."""
    return float(np.mean([o.result["terminal_speed_m_s"] for o in outs]))
