"""Campaigns: many sorties run headless to reproduce the paper's experiments.

The names below load on first use, so that importing a light submodule (``tune_options``,
which the command line's ``--help`` needs) does not pull numpy and the simulator in."""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "CAMPAIGNS": "definitions",
    "LAWS": "definitions",
    "CampaignError": "definitions",
    "build_jobs": "definitions",
    "LocalPoolRunner": "runner",
    "SortieJob": "runner",
    "SortieOutcome": "runner",
    "SortieRunner": "runner",
    "run_job": "runner",
}
__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
