"""Campaigns: many sorties run headless to reproduce the paper's experiments."""

from .definitions import CAMPAIGNS, LAWS, CampaignError, build_jobs
from .runner import LocalPoolRunner, SortieJob, SortieOutcome, SortieRunner, run_job

__all__ = [
    "CAMPAIGNS",
    "LAWS",
    "CampaignError",
    "LocalPoolRunner",
    "SortieJob",
    "SortieOutcome",
    "SortieRunner",
    "build_jobs",
    "run_job",
]
