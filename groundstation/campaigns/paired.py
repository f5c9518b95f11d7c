"""Two gain sets flown on the same sorties, compared pair by pair: per-sortie miss
differences, a seeded bootstrap CI and an exact sign test, for a study's held-out check or two
``campaign`` runs' results.json (``python -m groundstation.campaigns.paired BASE NEW``)."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .runner import SortieOutcome
from .tune_options import TuneError

BOOTSTRAP_RESAMPLES = 10_000


def sign_test_p(better: int, worse: int) -> float:
    """Two-sided exact sign test: the chance of a split at least this uneven between
    ``better`` and ``worse`` sorties (ties dropped) if either gain set were as likely to win."""
    m = better + worse
    if m == 0:
        return 1.0
    k = min(better, worse)
    tail = sum(math.comb(m, i) for i in range(k + 1)) / 2**m
    return min(1.0, 2.0 * tail)


def paired_comparison(
    base_miss_m: Sequence[float],
    new_miss_m: Sequence[float],
    base_hit: Sequence[bool] | None = None,
    new_hit: Sequence[bool] | None = None,
    seed: int = 0,
) -> dict[str, float]:
    """Two gain sets flown on the same sorties (same scenario and seed, pair by pair):
    the per-sortie miss difference d = new - base (m; negative: the new set missed by less),
    its mean with a seeded percentile-bootstrap 95 % CI, how many sorties improved or
    worsened (by more than 1e-9 m), the two-sided sign-test p, and the hits each set won
    that the other lost."""
    import numpy as np

    a = np.asarray(base_miss_m, dtype=float)
    b = np.asarray(new_miss_m, dtype=float)
    if a.shape != b.shape or a.ndim != 1 or a.size == 0:
        raise ValueError("paired_comparison needs two equal, non-empty lists of misses")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("miss distances must be finite")
    d = b - a
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, d.size, size=(BOOTSTRAP_RESAMPLES, d.size))
    boot = d[idx].mean(axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    better, worse = int(np.sum(d < -1e-9)), int(np.sum(d > 1e-9))
    out = {
        "n": int(d.size),
        "base_mean_m": float(a.mean()),
        "new_mean_m": float(b.mean()),
        "mean_diff_m": float(d.mean()),
        "ci95_low_m": float(lo),
        "ci95_high_m": float(hi),
        "median_diff_m": float(np.median(d)),
        "improved": better,
        "worsened": worse,
        "sign_test_p": sign_test_p(better, worse),
    }
    if base_hit is not None and new_hit is not None:
        if len(base_hit) != d.size or len(new_hit) != d.size:
            raise ValueError("hit flags must pair with the misses")
        out["hits_won"] = sum(1 for x, y in zip(base_hit, new_hit, strict=True) if y and not x)
        out["hits_lost"] = sum(1 for x, y in zip(base_hit, new_hit, strict=True) if x and not y)
    return out


def paired_outcomes(
    base: Sequence[SortieOutcome], new: Sequence[SortieOutcome]
) -> dict[str, float]:
    """:func:`paired_comparison` of two runs of the same sorties (in the same order)."""
    return paired_comparison(
        [float(o.result["miss_m"]) for o in base],
        [float(o.result["miss_m"]) for o in new],
        [o.result["outcome"] == "HIT" for o in base],
        [o.result["outcome"] == "HIT" for o in new],
    )


def paired_markdown(p: dict[str, float], label: str = "held-out") -> str:
    """One line: mean miss difference with its CI, sorties improved/worsened, sign test."""
    text = (
        f"Paired, {label} ({p['n']} sorties, same seeds): mean miss {p['base_mean_m']:.4f} -> "
        f"{p['new_mean_m']:.4f} m, difference {1000 * p['mean_diff_m']:+.1f} mm "
        f"(bootstrap 95 % CI {1000 * p['ci95_low_m']:+.1f} to {1000 * p['ci95_high_m']:+.1f} mm),"
        f" {p['improved']} sorties closer, {p['worsened']} wider, sign test p = "
        f"{p['sign_test_p']:.2g}"
    )
    if "hits_won" in p:
        text += f"; hits won {p['hits_won']}, lost {p['hits_lost']}"
    return text + "."


def _cell_of(labels: dict[str, Any]) -> str:
    """A campaign cell's name from a sortie's labels (the try and the target are not cells)."""
    keys = [k for k in labels if k not in ("try", "target", "law")]
    return ", ".join(f"{labels[k]}" for k in keys) or "all"


def _campaign_sorties(paths: Sequence[Path]) -> dict[tuple[str, int, str], dict[str, Any]]:
    """Sorties of one or more campaign runs keyed by (labels, seed, law)."""
    out: dict[tuple[str, int, str], dict[str, Any]] = {}
    for path in paths:
        path = Path(path)
        path = path / "results.json" if path.is_dir() else path
        try:
            sorties = json.loads(path.read_text(encoding="utf-8"))["sorties"]
            for s in sorties:
                key = (json.dumps(s["labels"], sort_keys=True), int(s["seed"]), str(s["law"]))
                if key in out:
                    raise TuneError(f"{path}: sortie {key} given twice")
                out[key] = s
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise TuneError(f"{path}: not a campaign's results.json ({exc})") from None
    return out


def paired_campaigns(
    base_results: Path | Sequence[Path], new_results: Path | Sequence[Path]
) -> dict[str, dict[str, float]]:
    """Pair campaign runs' ``results.json`` (one run or several, e.g. two seeds, each side)
    sortie by sortie (same labels, seed and law; refused if the sorties differ) and compare
    them per cell and over all sorties."""
    runs = [
        _campaign_sorties([r] if isinstance(r, (str, Path)) else list(r))
        for r in (base_results, new_results)
    ]
    if set(runs[0]) != set(runs[1]):
        raise TuneError("the two campaigns did not fly the same sorties (labels, seeds, laws)")
    keys = sorted(runs[0], key=lambda k: (_cell_of(json.loads(k[0])), k[1], k[2]))
    cells: dict[str, list[tuple[dict, dict]]] = {}
    for k in keys:
        cells.setdefault(_cell_of(json.loads(k[0])), []).append((runs[0][k], runs[1][k]))
    cells["all"] = [(runs[0][k], runs[1][k]) for k in keys]
    return {
        cell: paired_comparison(
            [a["miss_m"] for a, _ in pairs],
            [b["miss_m"] for _, b in pairs],
            [a["outcome"] == "HIT" for a, _ in pairs],
            [b["outcome"] == "HIT" for _, b in pairs],
        )
        for cell, pairs in cells.items()
    }


def paired_table(cmp: dict[str, dict[str, float]]) -> str:
    """Markdown table of :func:`paired_campaigns` (differences in mm, new - base)."""
    lines = [
        "| cell | n | mean miss base -> new | diff (95 % CI) | closer / wider | sign p | "
        "hits won / lost |",
        "|---|---|---|---|---|---|---|",
    ]
    for cell, p in cmp.items():
        lines.append(
            f"| {cell} | {p['n']} | {p['base_mean_m']:.4f} -> {p['new_mean_m']:.4f} m | "
            f"{1000 * p['mean_diff_m']:+.1f} mm ({1000 * p['ci95_low_m']:+.1f} to "
            f"{1000 * p['ci95_high_m']:+.1f}) | {p['improved']} / {p['worsened']} | "
            f"{p['sign_test_p']:.2g} | {p['hits_won']} / {p['hits_lost']} |"
        )
    return "\n".join(lines)


def main_paired(argv: Sequence[str] | None = None) -> int:
    """``python -m groundstation.campaigns.tune BASE NEW``: pair two campaign runs."""
    import argparse

    ap = argparse.ArgumentParser(
        prog="python -m groundstation.campaigns.tune",
        description="Pair two campaign runs of the same sorties (results.json or their "
        "folders): per-sortie miss differences NEW - BASE, bootstrap CI, sign test.",
    )
    ap.add_argument("base", help="the reference run(s): results.json or folders, a,b,...")
    ap.add_argument("new", help="the same sorties with the other gains: a,b,...")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    try:
        cmp = paired_campaigns(
            [Path(x) for x in args.base.split(",") if x],
            [Path(x) for x in args.new.split(",") if x],
        )
    except TuneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(cmp, indent=1) if args.json else paired_table(cmp))
    return 0


if __name__ == "__main__":
    raise SystemExit(main_paired())
