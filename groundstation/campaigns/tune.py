"""``groundstation tune``: an Optuna study over chosen gains against a campaign definition.

The search space comes from the gain declarations (:data:`onboard.gains.GAIN_SPECS`), narrowed
by the operator if asked. Every trial flies the same training sorties (campaign or scenarios x
seeds, with any ``--set`` changes) with its gains and scores them with the chosen objective;
the study lives in an Optuna storage (SQLite under the data folder by default), so running the
same command again resumes it and several processes or machines can work on it at once. At
the end the best gains and the defaults fly held-out seeds, a report with Optuna's plots is
written, and the best gains are saved as a named gain set the dashboard can load.
``python -m groundstation.campaigns.tune BASE NEW`` pairs two campaign runs of the same
sorties (defaults and tuned gains) the way the held-out check pairs its two runs.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from onboard.enums import DEFAULT_LAW
from onboard.gains import GAIN_NAMES, GAIN_SPECS, Gains

from ..scenario import ScenarioError, load_scenario, with_overrides
from .definitions import CAMPAIGNS, build_jobs
from .errors import TuneError
from .paired import main_paired, paired_campaigns, paired_comparison, paired_outcomes, sign_test_p
from .runner import SortieJob, SortieOutcome, SortieRunner
from .tune_figures import Figures, figures_markdown, objective_formula, score, write_tune_report
from .tune_options import DEFAULT_N, DEFAULT_SATURATION_PENALTY, OBJECTIVES

DEFAULT_OUT_ROOT = Path("logs") / "tune"
HEARTBEAT_S = 20  # a trial whose process stopped beating for GRACE_S is failed and retried
GRACE_S = 90
SQLITE_BUSY_TIMEOUT_S = 60.0  # open_study: how long a worker waits for the database file
# 2: success-cep's saturation penalty inside the CEP tie-break; a study scored with another
# version is refused rather than mixed (its losses are on another scale). success-mean was
# added at version 2 without changing how the other objectives score.
OBJECTIVE_VERSION = 2


@dataclass(frozen=True)
class GainRange:
    name: str
    low: float
    high: float
    log: bool = False


def parse_gain_space(text: str) -> tuple[GainRange, ...]:
    """``"K_y,k_p=0.01:0.1,k_v=0.5:50:log"`` -> ranges; a bare name takes its declared range,
    ``LO:HI`` narrows it (inside the declaration), ``:log`` samples on a log scale."""
    specs = {s.name: s for s in GAIN_SPECS}
    out: list[GainRange] = []
    for item in (x.strip() for x in text.split(",")):
        if not item:
            continue
        name, _, rng = item.partition("=")
        name = name.strip()
        if name not in specs:
            raise TuneError(f"--gains: unknown gain {name!r}; choose from {', '.join(GAIN_NAMES)}")
        s = specs[name]
        lo, hi, log = s.minimum, s.maximum, False
        if rng:
            parts = rng.split(":")
            if parts[-1] == "log":
                log, parts = True, parts[:-1]
            try:
                if len(parts) != 2:
                    raise ValueError
                lo, hi = float(parts[0]), float(parts[1])
            except ValueError:
                raise TuneError(
                    f"--gains {item!r}: expected NAME, NAME=LO:HI or NAME=LO:HI:log"
                ) from None
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise TuneError(f"--gains {item!r}: need finite LO < HI")
            if lo < s.minimum or hi > s.maximum:
                raise TuneError(
                    f"--gains {item!r}: outside {name}'s declared range "
                    f"[{s.minimum:g}, {s.maximum:g}] {s.unit}"
                )
        if log and lo <= 0:
            raise TuneError(f"--gains {item!r}: a log scale needs LO > 0")
        if any(r.name == name for r in out):
            raise TuneError(f"--gains lists {name} twice")
        out.append(GainRange(name, lo, hi, log))
    if not out:
        raise TuneError("--gains needs at least one gain, e.g. --gains K_y,K_z,k_p")
    return tuple(out)


@dataclass(frozen=True)
class TuneDefinition:
    """What a study optimises; a resumed study must have the same definition."""

    target: str  # a campaign name, or scenario names/files separated by commas
    space: tuple[GainRange, ...]
    n: int
    law: str = DEFAULT_LAW.value
    camera: str = "projected"
    seed: int = 0
    holdout_seed: int = 1
    overrides: tuple[tuple[str, Any], ...] = ()
    objective: str = "success-cep"
    saturation_penalty: float = DEFAULT_SATURATION_PENALTY
    objective_version: int = OBJECTIVE_VERSION

    def to_json_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["space"] = [dataclasses.asdict(r) for r in self.space]
        d["overrides"] = {k: v for k, v in self.overrides}
        return json.loads(json.dumps(d))  # the form the storage gives back

    def check(self) -> None:
        if self.n < 1:
            raise TuneError("--n must be at least 1")
        if self.objective not in OBJECTIVES:
            raise TuneError(f"--objective: choose one of {', '.join(OBJECTIVES)}")
        if not (math.isfinite(self.saturation_penalty) and self.saturation_penalty >= 0):
            raise TuneError("--saturation-penalty must be a finite number >= 0")
        if self.holdout_seed == self.seed:
            raise TuneError(
                "--holdout-seed must differ from --seed (held-out sorties are new ones)"
            )


def build_tune_jobs(defn: TuneDefinition, seed: int) -> list[SortieJob]:
    """The sorties of one evaluation: the campaign's (one law) or scenarios x n seeds."""
    overrides = dict(defn.overrides)
    if defn.target in CAMPAIGNS:
        jobs = build_jobs(defn.target, defn.n, (defn.law,), defn.camera, seed)
    else:
        names = [x.strip() for x in defn.target.split(",") if x.strip()]
        if not names:
            raise TuneError(f"choose a campaign ({', '.join(CAMPAIGNS)}) or scenarios")
        jobs = []
        for name in names:
            try:
                sc = load_scenario(name)
            except ScenarioError as exc:
                raise TuneError(
                    f"{name!r} is neither a campaign ({', '.join(CAMPAIGNS)}) nor a scenario: {exc}"
                ) from None
            for k in range(defn.n):
                labels = (("scenario", sc.name), ("law", defn.law), ("try", k))
                jobs.append(
                    SortieJob(len(jobs), sc, defn.law, seed * 1000 + k, defn.camera, labels)
                )
    if overrides:
        jobs = [
            dataclasses.replace(j, scenario=with_overrides(j.scenario, overrides)) for j in jobs
        ]
    return jobs


def with_gains(jobs: Sequence[SortieJob], gains: dict[str, float]) -> list[SortieJob]:
    """The same sorties flown with some gains changed (checked against the declarations)."""
    if not gains:
        return list(jobs)
    changes = {f"gains.{k}": float(v) for k, v in gains.items()}
    return [dataclasses.replace(j, scenario=with_overrides(j.scenario, changes)) for j in jobs]


def evaluate(
    jobs: Sequence[SortieJob],
    gains: dict[str, float],
    runner: SortieRunner,
    defn: TuneDefinition,
    on_done: Callable[[SortieOutcome], None] | None = None,
) -> Figures:
    return score(
        runner.run(with_gains(jobs, gains), on_done=on_done),
        defn.objective,
        defn.saturation_penalty,
    )


def _score(outcomes: Sequence[SortieOutcome], defn: TuneDefinition) -> Figures:
    return score(outcomes, defn.objective, defn.saturation_penalty)


def default_storage_url(data_dir: Path) -> str:
    return f"sqlite:///{(Path(data_dir) / 'studies.db').resolve()}"


def open_study(storage_url: str, study_name: str, defn: TuneDefinition, sampler_seed: int):
    """Create or load the study; a loaded study must have been made with ``defn``. Trials of
    a process that stopped beating (crash, kill) are failed and flown again by a live one."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    engine_kwargs = {}
    if storage_url.startswith("sqlite:///"):
        Path(storage_url[len("sqlite:///") :]).parent.mkdir(parents=True, exist_ok=True)
        # workers sharing the file wait for each other's writes this long, not sqlite3's 5 s
        # default (a worker that gives up first fails its trial: "database is locked")
        engine_kwargs["connect_args"] = {"timeout": SQLITE_BUSY_TIMEOUT_S}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            storage = optuna.storages.RDBStorage(
                storage_url,
                engine_kwargs=engine_kwargs,
                heartbeat_interval=HEARTBEAT_S,
                grace_period=GRACE_S,
                heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback(
                    max_retry=2
                ),
            )
        study = optuna.create_study(
            storage=storage,
            study_name=study_name,
            sampler=optuna.samplers.TPESampler(seed=sampler_seed),
            direction="minimize",
            load_if_exists=True,
        )
    except (ImportError, ValueError, KeyError) as exc:
        raise TuneError(f"--storage {storage_url}: {exc}") from None
    except Exception as exc:  # SQLAlchemy's errors: bad URL, unreachable database
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise TuneError(f"--storage {storage_url}: {first}") from None
    want = defn.to_json_dict()
    have = study.user_attrs.get("definition")
    if have is None:
        study.set_user_attr("definition", want)
    elif have != want:
        diff = sorted(k for k in set(want) | set(have) if want.get(k) != have.get(k))
        raise TuneError(
            f"study {study_name!r} in {storage_url} was made with a different definition "
            f"(differs in {', '.join(diff)}); pick another --study or repeat its options"
        )
    return study


def default_gainset(study_name: str) -> str:
    """``tuned-STUDY``, cut to the 48 characters a gain set name may have."""
    return f"tuned-{study_name}"[:48].rstrip(".-")


def _defaults_in_space(space: Sequence[GainRange], base: Gains) -> dict[str, float] | None:
    vals = {r.name: getattr(base, r.name) for r in space}
    return vals if all(r.low <= vals[r.name] <= r.high for r in space) else None


def run_tune(
    defn: TuneDefinition,
    trials: int,
    runner: SortieRunner,
    storage_url: str,
    study_name: str,
    data_dir: Path,
    sampler_seed: int = 0,
    out: Path | None = None,
    gainset: str | None = None,
    progress: bool = True,
    command: str = "",
) -> dict[str, Any]:
    """Run the study up to ``trials`` complete trials (all workers together), then check the
    best gains on held-out seeds, write the report and save the gain set."""
    import optuna
    from tqdm import tqdm

    from ..app.gainsets import GainSetStore

    defn.check()
    if trials < 1:
        raise TuneError("--trials must be at least 1")
    train = build_tune_jobs(defn, defn.seed)
    held_out = build_tune_jobs(defn, defn.holdout_seed)
    base = train[0].scenario.gains_obj()  # the gains the campaign flies today
    store = GainSetStore(Path(data_dir) / "gainsets")
    gainset = gainset or default_gainset(study_name)
    store._path(gainset)  # checks the name before any work
    study = open_study(storage_url, study_name, defn, sampler_seed)
    done_states = (optuna.trial.TrialState.COMPLETE,)
    complete = len(study.get_trials(deepcopy=False, states=done_states))
    remaining = max(0, trials - complete)
    if not study.trials:
        defaults = _defaults_in_space(defn.space, base)
        if defaults is not None:  # trial 0 flies the defaults: the baseline in the history
            study.enqueue_trial(defaults, user_attrs={"defaults": True})

    bar = tqdm(
        total=remaining * len(train),
        desc=f"tune {study_name}",
        unit="sortie",
        file=sys.stderr,
        disable=not progress or remaining == 0,
    )

    def objective(trial: optuna.Trial) -> float:
        gains = {r.name: trial.suggest_float(r.name, r.low, r.high, log=r.log) for r in defn.space}
        fig = evaluate(train, gains, runner, defn, on_done=lambda _o: bar.update(1))
        for k, v in fig.to_json_dict().items():
            trial.set_user_attr(k, v)
        return fig.loss

    def after(study: optuna.Study, trial: optuna.trial.FrozenTrial) -> None:
        try:
            best = study.best_trial
            bar.set_postfix(trial=trial.number, best=f"#{best.number} {best.value:.4f}")
        except ValueError:
            pass

    t0 = time.perf_counter()
    if remaining:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            study.optimize(
                objective,
                n_trials=remaining,
                callbacks=[optuna.study.MaxTrialsCallback(trials, states=done_states), after],
                gc_after_trial=False,
            )
    bar.close()
    study_wall_s = time.perf_counter() - t0
    best = study.best_trial
    best_gains = {r.name: float(best.params[r.name]) for r in defn.space}
    t1 = time.perf_counter()
    fields = list(Figures.__dataclass_fields__)
    baseline = [
        t
        for t in study.get_trials(deepcopy=False, states=done_states)
        if t.user_attrs.get("defaults")
    ]  # trial 0 flew the defaults on the training sorties already
    held_base = runner.run(with_gains(held_out, {}))
    held_best = runner.run(with_gains(held_out, best_gains))
    figures = {
        "defaults": {
            "train": {k: baseline[0].user_attrs[k] for k in fields}
            if baseline
            else evaluate(train, {}, runner, defn).to_json_dict(),
            "held_out": _score(held_base, defn).to_json_dict(),
        },
        "best": {
            "train": {k: best.user_attrs[k] for k in fields},
            "held_out": _score(held_best, defn).to_json_dict(),
        },
        "paired_held_out": paired_outcomes(held_base, held_best),
    }
    check_wall_s = time.perf_counter() - t1
    tuned = Gains.from_mapping({**base.to_dict(), **best_gains}, source="tuned gains")
    store.save(gainset, tuned)

    from .driver import fresh_out_dir

    out = Path(out) if out else fresh_out_dir(study_name, DEFAULT_OUT_ROOT)
    states = [t.state.name for t in study.trials]
    meta = {
        "study": study_name,
        "storage": storage_url,
        "command": command,
        "definition": defn.to_json_dict(),
        "objective_formula": objective_formula(defn.objective, defn.saturation_penalty),
        "trials_wanted": trials,
        "trials_run_now": remaining,
        "trials_complete": states.count("COMPLETE"),
        "trials_total": len(states),
        "train_sorties_per_trial": len(train),
        "held_out_sorties": len(held_out),
        "sampler_seed": sampler_seed,
        "workers": getattr(runner, "workers", None),
        "backend": type(runner).__name__,
        "study_wall_s": study_wall_s,
        "held_out_check_wall_s": check_wall_s,
        "best_trial": best.number,
        "best_gains": best_gains,
        "default_gains": {r.name: getattr(base, r.name) for r in defn.space},
        "gainset": gainset,
        "gainset_file": str(store._path(gainset)),
    }
    files = write_tune_report(out, study, meta, figures)
    return {"out": str(out), "files": files, "meta": meta, "figures": figures}


def main_tune(args) -> int:
    import shlex

    from ..app.gainsets import GainSetError, GainSetStore, default_data_dir
    from ..scenario import parse_overrides
    from .ray_runner import make_runner

    defn = TuneDefinition(
        target=args.target,
        space=parse_gain_space(args.gains),
        n=args.n if args.n is not None else DEFAULT_N,
        law=args.law,
        camera=args.camera,
        seed=args.seed,
        holdout_seed=args.seed + 1 if args.holdout_seed is None else args.holdout_seed,
        overrides=tuple(parse_overrides(args.set).items()),
        objective=args.objective,
        saturation_penalty=args.saturation_penalty,
    )
    defn.check()
    build_tune_jobs(defn, defn.seed)  # scenarios and --set checked before any work
    data_dir = Path(args.data_dir) if args.data_dir else default_data_dir()
    storage = args.storage or default_storage_url(data_dir)
    stems = "_".join(Path(x.strip()).stem for x in args.target.split(",") if x.strip())
    study_name = args.study or f"{stems}-{args.law}"
    command = "groundstation " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    try:
        GainSetStore(data_dir / "gainsets")._path(args.gainset or default_gainset(study_name))
        if args.trials < 1:
            raise TuneError("--trials must be at least 1")
        with make_runner(args.backend, args.workers, args.ray_address) as runner:
            res = run_tune(
                defn,
                args.trials,
                runner,
                storage,
                study_name,
                data_dir,
                sampler_seed=args.sampler_seed,
                out=Path(args.out) if args.out else None,
                gainset=args.gainset,
                progress=not args.json,
                command=command,
            )
    except GainSetError as exc:
        raise TuneError(str(exc)) from None
    if args.json:
        print(json.dumps({"out": res["out"], "meta": res["meta"], "figures": res["figures"]}))
    else:
        print(figures_markdown(res["meta"], res["figures"]))
        print(f"\nreport: {res['out']}/report.md")
    return 0


__all__ = [
    "Figures",
    "GainRange",
    "TuneDefinition",
    "TuneError",
    "build_tune_jobs",
    "figures_markdown",
    "main_paired",
    "main_tune",
    "objective_formula",
    "paired_campaigns",
    "paired_comparison",
    "paired_outcomes",
    "parse_gain_space",
    "run_tune",
    "score",
    "sign_test_p",
    "write_tune_report",
]

if __name__ == "__main__":  # python -m groundstation.campaigns.tune BASE NEW: pair two runs
    raise SystemExit(main_paired())
