"""``groundstation tune``'s options and objectives: light (no numpy, no Optuna), so the
command line's ``--help`` stays fast; :mod:`.tune` runs the study."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from onboard.enums import DEFAULT_LAW, GuidanceLaw, codes

from ..scenario import CAMERA_MODES

OBJECTIVES = ("success-cep", "success-mean", "cep", "success")
OBJECTIVE_HELP = {
    "success-cep": "HIT rate first, then CEP: (1 - HIT rate) + CEP/(CEP + 1 m)/(2 N)",
    "success-mean": ("HIT rate first, then mean miss: (1 - HIT rate) + mean/(mean + 1 m)/(2 N)"),
    "cep": "CEP (median miss, m)",
    "success": "1 - HIT rate",
}
DEFAULT_SATURATION_PENALTY = 0.05
DEFAULT_N = 5  # per cell: a trial of the wind campaign is 4 speeds x 5 tries = 20 sorties


def add_tune_arguments(
    t: Any,
    set_help: str,
    count: Callable[[str], int] = int,
    seed: Callable[[str], int] = int,
    out_dir: Callable[[str], str] = str,
) -> None:
    """``groundstation tune``'s options (the CLI adds ``--backend`` and ``--ray-address`` and
    hands in its checks: ``count`` >= 1, ``seed`` >= 0, ``out_dir`` a writable folder)."""
    t.add_argument("target", help="campaign (static|moving|wind|outdoor) or scenarios a,b,...")
    t.add_argument("--gains", required=True, help="NAME[=LO:HI[:log]],... (ranges: onboard gains)")
    t.add_argument("--trials", type=count, default=50, help="complete trials wanted in the study")
    t.add_argument(
        "--n", type=count, default=None, help=f"per cell: targets/seeds/tries (default {DEFAULT_N})"
    )
    t.add_argument("--law", default=DEFAULT_LAW.value, choices=codes(GuidanceLaw))
    t.add_argument("--camera", default="projected", choices=CAMERA_MODES)
    t.add_argument("--seed", type=seed, default=0, help="training seed")
    t.add_argument("--holdout-seed", type=seed, default=None, help="held-out seed (default seed+1)")
    t.add_argument("--objective", default="success-cep", choices=OBJECTIVES)
    t.add_argument("--saturation-penalty", type=float, default=DEFAULT_SATURATION_PENALTY)
    t.add_argument("--study", default=None, help="study name (default TARGET-LAW)")
    t.add_argument(
        "--storage", default=None, help="Optuna storage URL (default: SQLite in data dir)"
    )
    t.add_argument("--sampler-seed", type=seed, default=0, help="TPE sampler seed")
    t.add_argument("--workers", type=count, default=None, help="processes (default: cores)")
    t.add_argument("--gainset", default=None, help="saved gain set's name (tuned-STUDY)")
    t.add_argument("--data-dir", default=None, help="gain sets and studies (default ~/.peregrine)")
    t.add_argument("--out", type=out_dir, help="report folder (default logs/tune/...)")
    t.add_argument("--json", action="store_true", help="print the figures as JSON")
    t.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help=set_help)
