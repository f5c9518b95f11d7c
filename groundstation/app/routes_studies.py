"""``/api/studies``: the Optuna studies ``groundstation tune`` stored (SQLite under the data
folder by default), their trials and best-so-far curve, and flying one trial's gains beside the
defaults: the defaults fly first, recorded, then the trial's gains fly on screen with that
sortie overlaid (the compare overlay), on the study's first training sortie. Flying changes
the vehicle's behaviour, so it sits behind the token like every route."""

from __future__ import annotations

import asyncio
import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fastapi import APIRouter, HTTPException
from pydantic import BaseModel, ConfigDict, Field

from onboard.gains import GainError, Gains

from ..scenario import ScenarioError
from .api_models import Speed, Status
from .protocol import Session
from .routes_sortie import command
from .session_config import SortieConfig


class FlyTrialRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    speed: Speed = "1"
    job: int = Field(0, ge=0, description="which training sortie of the study (0: the first)")


def _finite(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


def _load(storage_url: str, name: str | None = None):
    """Optuna (imported here: it is slow to import) and the study ``name`` (None: none)."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    if name is None:
        return optuna, None
    try:
        return optuna, optuna.load_study(study_name=name, storage=storage_url)
    except KeyError:
        raise HTTPException(404, f"no study named {name!r}") from None


def list_studies(storage_url: str, db_path: Path | None) -> list[dict[str, Any]]:
    if db_path is not None and not db_path.is_file():
        return []  # no study yet: do not create an empty database by looking
    optuna, _ = _load(storage_url)
    out = []
    for s in optuna.study.get_all_study_summaries(storage_url):
        d = s.user_attrs.get("definition") or {}
        best = s.best_trial
        out.append(
            {
                "name": s.study_name,
                "trials": s.n_trials,
                "target": d.get("target"),
                "law": d.get("law"),
                "objective": d.get("objective"),
                "gains": [r["name"] for r in d.get("space", [])],
                "best_value": None if best is None else _finite(best.value),
                "best_trial": None if best is None else best.number,
            }
        )
    return out


def study_detail(storage_url: str, name: str) -> dict[str, Any]:
    optuna, study = _load(storage_url, name)
    trials, best_so_far, best = [], [], math.inf
    for t in sorted(study.get_trials(deepcopy=False), key=lambda t: t.number):
        value = _finite(t.value) if t.state == optuna.trial.TrialState.COMPLETE else None
        if value is not None:
            best = min(best, value)
        trials.append(
            {
                "number": t.number,
                "state": t.state.name,
                "value": value,
                "params": dict(t.params),
                "defaults": bool(t.user_attrs.get("defaults")),
                "figures": {
                    k: _finite(t.user_attrs.get(k))
                    for k in ("success_rate", "cep_m", "mean_miss_m", "saturated", "n")
                },
            }
        )
        best_so_far.append(None if math.isinf(best) else best)
    return {
        "name": name,
        "definition": study.user_attrs.get("definition"),
        "trials": trials,
        "best_so_far": best_so_far,  # per trial, in trial order (lower is better)
    }


def _first_sortie(definition: dict[str, Any], job: int):
    """The study's training sortie ``job`` (scenario, law, seed, camera), as tune flew it."""
    from ..campaigns.tune import GainRange, TuneDefinition, TuneError, build_tune_jobs

    try:
        defn = TuneDefinition(
            target=definition["target"],
            space=tuple(GainRange(**r) for r in definition["space"]),
            n=int(definition["n"]),
            law=definition["law"],
            camera=definition["camera"],
            seed=int(definition["seed"]),
            holdout_seed=int(definition["holdout_seed"]),
            overrides=tuple(definition.get("overrides", {}).items()),
            objective=definition["objective"],
            saturation_penalty=float(definition["saturation_penalty"]),
        )
        jobs = build_tune_jobs(defn, defn.seed)
    except (KeyError, TypeError, ValueError, TuneError, ScenarioError) as exc:
        raise HTTPException(422, f"the study's definition cannot be flown here: {exc}") from None
    if job >= len(jobs):
        raise HTTPException(422, f"the study has {len(jobs)} training sorties (job 0..)")
    return jobs[job]


def _fly_recorded(job, log_dir: Path) -> Path:
    """Fly ``job`` headless, recorded to ``log_dir``; the recording's path."""
    from ..recording.writer import SortieRecorder
    from ..sim.simulation import Simulation

    rec = SortieRecorder(log_dir)
    sim = Simulation(
        job.scenario, job.law, job.seed, job.camera, keep_records=False, observers=(rec,)
    )
    sim.run()
    return rec.path


def router(session: Session, storage: Callable[[], str], log_dir: Path | None) -> APIRouter:
    """``storage``: the studies' storage URL, asked at the first request (finding it may
    import the tuning code, slow to import, which the server's start does not wait for)."""
    r = APIRouter()

    @functools.cache
    def where() -> tuple[str, Path | None]:
        url = storage()
        return url, Path(url[len("sqlite:///") :]) if url.startswith("sqlite:///") else None

    @r.get("/api/studies", tags=["studies"])
    async def studies() -> list[dict[str, Any]]:
        """The gain-tuning studies (``groundstation tune``) in the server's storage."""
        return await asyncio.to_thread(lambda: list_studies(*where()))

    @r.get("/api/studies/{name}", tags=["studies"])
    async def study(name: str) -> dict[str, Any]:
        """A study's trials (gains, loss, figures) and its best-so-far loss per trial."""
        return await asyncio.to_thread(lambda: study_detail(where()[0], name))

    @r.post("/api/studies/{name}/trials/{number}/fly", tags=["studies"])
    async def fly_trial(name: str, number: int, req: FlyTrialRequest | None = None) -> Status:
        """Fly trial ``number``'s gains beside the defaults: the study's training sortie with
        the scenario's gains flies first, recorded; then the trial's gains fly it on screen
        at ``speed`` with the defaults' sortie overlaid."""
        req = req or FlyTrialRequest()
        if log_dir is None or not session.simulated:
            raise HTTPException(409, "flying a trial needs the simulator with a log folder")
        detail = await asyncio.to_thread(lambda: study_detail(where()[0], name))
        trial = next((t for t in detail["trials"] if t["number"] == number), None)
        if trial is None:
            raise HTTPException(404, f"study {name!r} has no trial {number}")
        if trial["state"] != "COMPLETE" or not trial["params"]:
            raise HTTPException(409, f"trial {number} is {trial['state'].lower()}: no gains")
        job = _first_sortie(detail["definition"] or {}, req.job)
        try:
            gains = Gains.from_mapping({**job.scenario.gains, **trial["params"]})
        except GainError as exc:
            raise HTTPException(422, f"trial {number}'s gains: {exc}") from None
        defaults = await asyncio.to_thread(_fly_recorded, job, Path(log_dir))
        config = SortieConfig(job.scenario, job.law, job.seed, job.camera, req.speed)
        # the trial's gains fly this sortie only: the operator's gains are left as they were
        command(session, session.start, config, None, gains, f"study {name} trial #{number}")
        return command(session, session.compare_with, defaults, defaults.name)

    return r
