"""Statistics of sortie sets: CEP (median miss, DESIGN §6), spread, success."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def miss_stats(misses_m: Sequence[float]) -> dict[str, float]:
    """n, CEP (median), mean, std, 90th percentile, min and max of miss distances (m)."""
    if not misses_m:
        raise ValueError("no misses to aggregate")
    a = np.asarray(misses_m, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError("miss distances must be finite")
    return {
        "n": int(a.size),
        "cep_m": float(np.median(a)),
        "mean_m": float(a.mean()),
        "std_m": float(a.std(ddof=1)) if a.size > 1 else 0.0,
        "p90_m": float(np.percentile(a, 90)),
        "min_m": float(a.min()),
        "max_m": float(a.max()),
    }


def success_rate(outcomes: Sequence[str]) -> float:
    """Fraction of sorties whose outcome is HIT."""
    if not outcomes:
        raise ValueError("no outcomes")
    return sum(o == "HIT" for o in outcomes) / len(outcomes)


def median_iqr(values: Sequence[float]) -> tuple[float, float]:
    """Median and interquartile range (Q3 - Q1)."""
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return math.nan, math.nan
    q1, med, q3 = np.percentile(a, [25, 50, 75])
    return float(med), float(q3 - q1)
