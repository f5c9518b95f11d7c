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

from onboard.gains import GAIN_NAMES, GAIN_SPECS, Gains

from ..scenario import ScenarioError, load_scenario, with_overrides
from .aggregate import success_rate
from .definitions import CAMPAIGNS, CampaignError, build_jobs
from .runner import SortieJob, SortieOutcome, SortieRunner
from .tune_options import DEFAULT_N, DEFAULT_SATURATION_PENALTY, OBJECTIVE_HELP, OBJECTIVES

DEFAULT_OUT_ROOT = Path("logs") / "tune"
HEARTBEAT_S = 20  # a trial whose process stopped beating for GRACE_S is failed and retried
GRACE_S = 90
SQLITE_BUSY_TIMEOUT_S = 60.0  # open_study: how long a worker waits for the database file
# 2: success-cep's saturation penalty inside the CEP tie-break; a study scored with another
# version is refused rather than mixed (its losses are on another scale). success-mean was
# added at version 2 without changing how the other objectives score.
OBJECTIVE_VERSION = 2


class TuneError(CampaignError):
    """A bad tuning option or a study that does not match the command."""


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
    law: str = "png"
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


@dataclass
class Figures:
    """What a set of sorties scored: HIT rate, CEP (median miss, m), mean miss (m), mean
    share of control ticks saturated, and the objective's loss (lower is better)."""

    n: int
    success_rate: float
    cep_m: float
    mean_miss_m: float
    saturated: float
    loss: float

    def to_json_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)


def score(outcomes: Sequence[SortieOutcome], objective: str, saturation_penalty: float) -> Figures:
    """The objective (minimised). The saturation penalty adds ``penalty x`` the mean share of
    saturated ticks (in metres for the miss objectives). ``success-cep`` is lexicographic: its
    tie-break c/(c + 1 m)/(2 N), c = CEP + penalty x saturated share, stays below half of one
    sortie's share of the HIT rate whatever the penalty, so no CEP gain buys back a lost hit,
    and when every sortie hits the CEP is not drowned by a penalty outside the tie-break.
    ``success-mean`` is the same with the mean miss in place of the CEP: every sortie's miss
    counts, where a median of N moves with whichever sortie sits in the middle."""
    n = len(outcomes)
    if n == 0:
        raise ValueError("no sorties to score")
    misses = sorted(float(o.result["miss_m"]) for o in outcomes)
    success = success_rate([o.result["outcome"] for o in outcomes])
    cep = float(misses[n // 2] if n % 2 else 0.5 * (misses[n // 2 - 1] + misses[n // 2]))
    sat = sum(float((o.trace or {}).get("saturated_fraction", 0.0)) for o in outcomes) / n
    cost = saturation_penalty * sat
    mean = sum(misses) / n
    if objective in ("success-cep", "success-mean"):
        c = (cep if objective == "success-cep" else mean) + cost
        loss = (1.0 - success) + c / (c + 1.0) / (2 * n)
    elif objective == "cep":
        loss = cep + cost
    elif objective == "success":
        loss = (1.0 - success) + cost
    else:
        raise TuneError(f"unknown objective {objective!r}")
    return Figures(n, success, cep, mean, sat, loss)


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


def objective_formula(objective: str, saturation_penalty: float) -> str:
    """The objective in words and symbols, with the penalty where :func:`score` adds it."""
    text = OBJECTIVE_HELP[objective]
    if not saturation_penalty:
        return text
    if objective in ("success-cep", "success-mean"):
        stat = "CEP" if objective == "success-cep" else "mean"
        return text.replace(f"{stat}/({stat} + 1 m)", "c/(c + 1 m)") + (
            f", c = {stat} + {saturation_penalty:g} m x saturated share"
        )
    return text + f" + {saturation_penalty:g}{' m' if objective == 'cep' else ''} x saturated share"


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


def _fig_row(label: str, f: dict[str, float]) -> str:
    return (
        f"| {label} | {100 * f['success_rate']:.0f} % | {f['cep_m']:.3f} m | "
        f"{f['mean_miss_m']:.3f} m | {100 * f['saturated']:.1f} % | {f['loss']:.4f} |"
    )


def figures_markdown(meta: dict[str, Any], figures: dict[str, Any]) -> str:
    d = meta["definition"]
    lines = [
        f"Study `{meta['study']}`: {meta['trials_complete']} complete trials, "
        f"{meta['train_sorties_per_trial']} training sorties each (seed {d['seed']}), "
        f"{meta['held_out_sorties']} held-out sorties (seed {d['holdout_seed']}); "
        f"objective `{d['objective']}`: {meta['objective_formula']}.",
        "",
        "| gains | HIT rate | CEP | mean miss | saturated | loss |",
        "|---|---|---|---|---|---|",
        _fig_row("defaults, train", figures["defaults"]["train"]),
        _fig_row(f"best (trial {meta['best_trial']}), train", figures["best"]["train"]),
        _fig_row("defaults, held-out", figures["defaults"]["held_out"]),
        _fig_row(f"best (trial {meta['best_trial']}), held-out", figures["best"]["held_out"]),
        "",
        paired_markdown(figures["paired_held_out"]) if "paired_held_out" in figures else "",
        "",
        "| gain | default | best | searched |",
        "|---|---|---|---|",
    ]
    for r in d["space"]:
        name = r["name"]
        lines.append(
            f"| {name} | {meta['default_gains'][name]:g} | {meta['best_gains'][name]:.4g} | "
            f"[{r['low']:g}, {r['high']:g}]{' log' if r['log'] else ''} |"
        )
    lines += ["", f"Saved as gain set `{meta['gainset']}` ({meta['gainset_file']})."]
    return "\n".join(lines)


def write_tune_report(
    out: Path, study: Any, meta: dict[str, Any], figures: dict[str, Any]
) -> list[str]:
    """report.md, results.json (every trial) and Optuna's plots as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import optuna
    from optuna.visualization import matplotlib as ovm

    out.mkdir(parents=True, exist_ok=True)
    complete = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    # The success-cep loss spans decades (a lost hit costs 1/N, a centimetre of CEP 1e-4):
    # on a linear axis every trial that hits looks the same, so plot log10(loss) when it can.
    log = bool(complete) and all(t.value is not None and t.value > 0 for t in complete)
    kw: dict[str, Any] = (
        {"target": lambda t: math.log10(t.value), "target_name": "log10(loss)"} if log else {}
    )
    plots = {
        "optimization_history.png": lambda: ovm.plot_optimization_history(study),
        "param_importances.png": lambda: ovm.plot_param_importances(study, **kw),
        "parallel_coordinate.png": lambda: ovm.plot_parallel_coordinate(study, **kw),
    }
    files, skipped = [], []
    for name, plot in plots.items():
        if name == "param_importances.png" and (len(complete) < 2 or len(meta["best_gains"]) < 2):
            skipped.append(f"{name} (needs 2 or more trials and gains)")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ax = plot()
        fig = ax.figure if hasattr(ax, "figure") else ax.flat[0].figure
        if log and name == "optimization_history.png":
            ax.set_yscale("log")  # keeps Optuna's best-so-far line, which a target would drop
            ax.set_ylabel("loss (log scale)")
        fig.set_size_inches(13 if name.startswith("parallel") else 9, 6)
        fig.tight_layout()
        fig.savefig(out / name, dpi=100)
        plt.close(fig)
        files.append(name)
    trials = [
        {
            "number": t.number,
            "state": t.state.name,
            "loss": t.value,
            "params": t.params,
            "figures": {k: t.user_attrs.get(k) for k in Figures.__dataclass_fields__},
            "defaults": bool(t.user_attrs.get("defaults")),
        }
        for t in study.trials
    ]
    (out / "results.json").write_text(
        json.dumps({"meta": meta, "figures": figures, "trials": trials}, indent=1),
        encoding="utf-8",
    )
    md = [
        f"# Gain tuning: {meta['study']}",
        "",
        f"`{meta['command']}`" if meta["command"] else "",
        "",
        figures_markdown(meta, figures),
        "",
        f"Storage `{meta['storage']}`; this run: {meta['trials_run_now']} trials in "
        f"{meta['study_wall_s']:.1f} s wall, held-out check {meta['held_out_check_wall_s']:.1f} s "
        f"({meta['backend']}, {meta['workers']} workers).",
        "",
    ]
    md += [f"![{f}]({f})" for f in files]
    if skipped:
        md += ["", "Not drawn: " + ", ".join(skipped)]
    (out / "report.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    return ["report.md", "results.json", *files]


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
