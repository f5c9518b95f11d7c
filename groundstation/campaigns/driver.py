"""``groundstation campaign``: build the jobs, run them with a progress bar, aggregate, write
the report."""

from __future__ import annotations

import dataclasses
import json
import shlex
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import tomli_w
from tqdm import tqdm

from ..scenario.overrides import parse_overrides, with_overrides
from ..sim.camera import CAMERA_MODES
from .definitions import DEFAULT_LAWS, CampaignError, build_jobs, get_campaign
from .report import tables_markdown, write_report
from .runner import LocalPoolRunner, SortieRunner

DEFAULT_OUT_ROOT = Path("logs") / "campaigns"


def fresh_out_dir(name: str, root: Path = DEFAULT_OUT_ROOT) -> Path:
    """logs/campaigns/<name>-<UTC time>/, never an existing folder."""
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    out = root / f"{name}-{stamp}"
    k = 1
    while out.exists():
        k += 1
        out = root / f"{name}-{stamp}-{k}"
    return out


def run_campaign(
    name: str,
    n: int | None = None,
    laws: tuple[str, ...] = DEFAULT_LAWS,
    camera: str = "projected",
    seed: int = 0,
    workers: int | None = None,
    out: Path | None = None,
    runner: SortieRunner | None = None,
    progress: bool = True,
    command: str | None = None,
    log_dir: Path | None = None,
    overrides: dict[str, Any] | None = None,
    only: dict[str, tuple[str, ...]] | None = None,
) -> dict[str, Any]:
    """Run a campaign and write its report; ``overrides`` (``{"camera.delay_s": 0}``, see
    :func:`with_overrides`) change every sortie's scenario, checked before anything runs;
    ``only`` ({label: values}, :func:`.definitions.parse_only`) flies a subset of its cells."""
    campaign = get_campaign(name)
    if camera not in CAMERA_MODES:
        raise CampaignError(f"unknown camera mode {camera!r}; choose one of {CAMERA_MODES}")
    n = campaign.default_n if n is None else n
    jobs = build_jobs(name, n, laws, camera, seed, only)
    if overrides:
        jobs = [
            dataclasses.replace(j, scenario=with_overrides(j.scenario, overrides)) for j in jobs
        ]
    if log_dir is not None:
        jobs = [dataclasses.replace(j, log_dir=str(log_dir)) for j in jobs]
    runner = runner or LocalPoolRunner(workers)
    n_workers = getattr(runner, "workers", None)
    bar = tqdm(
        total=len(jobs),
        desc=f"campaign {name}",
        unit="sortie",
        file=sys.stderr,
        disable=not progress,
    )
    t0 = time.perf_counter()
    outcomes = runner.run(jobs, on_done=lambda _o: bar.update(1))
    wall_s = time.perf_counter() - t0
    bar.close()
    summary = campaign.summarize(outcomes)
    sim_s = sum(o.result["sim_time_s"] for o in outcomes)
    meta = {
        "campaign": name,
        "command": command
        or f"groundstation campaign {name} --n {n} --laws {','.join(laws)} "
        f"--camera {camera} --seed {seed}"
        + "".join(f" --set {k}={_toml_value(v)}" for k, v in (overrides or {}).items())
        + "".join(f" --only {k}={','.join(v)}" for k, v in (only or {}).items()),
        "n": n,
        "what_n_counts": campaign.what_n_counts,
        "laws": list(laws),
        "camera": camera,
        "seed": seed,
        "overrides": dict(overrides or {}),
        "only": {k: list(v) for k, v in (only or {}).items()},
        # the state-estimate model every sortie flew with (overrides apply to all of them)
        "estimate": dataclasses.asdict(jobs[0].scenario.estimate) if jobs else {},
        # the error profiles flown ("ideal": ideal sensors, analysis only)
        "profiles": sorted({str(o.result.get("profile", "")) for o in outcomes}),
        "workers": n_workers,
        "backend": type(runner).__name__,
        "sorties": len(outcomes),
        "sim_time_s": sim_s,
        "wall_s": wall_s,
        "throughput_sim_s_per_s": sim_s / wall_s if wall_s > 0 else float("inf"),
    }
    out = out or fresh_out_dir(name)
    files = write_report(out, name, meta, summary, outcomes)
    return {"out": str(out), "files": files, "meta": meta, "summary": summary, "outcomes": outcomes}


def _toml_value(v: Any) -> str:
    return tomli_w.dumps({"v": v})[4:].strip()


def main_campaign(args) -> int:
    from ..sim.profiles import label
    from .definitions import parse_laws, parse_only
    from .ray_runner import make_runner

    get_campaign(args.name)
    laws = parse_laws(args.laws)
    overrides = parse_overrides(args.set)
    only = parse_only(args.only)
    command = "groundstation " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    with make_runner(args.backend, args.workers, args.ray_address) as runner:
        res = run_campaign(
            args.name,
            args.n,
            laws,
            args.camera,
            args.seed,
            args.workers,
            Path(args.out) if args.out else None,
            runner=runner,
            progress=not args.json,
            command=command,
            log_dir=Path(args.log) if args.log else None,
            overrides=overrides,
            only=only,
        )
    meta = res["meta"]
    if args.json:
        print(
            json.dumps(
                {"out": res["out"], "meta": meta, "summary": res["summary"]},
                default=lambda x: list(x) if isinstance(x, tuple) else str(x),
            )
        )
    else:
        print(tables_markdown(args.name, res["summary"], res["outcomes"]))
        print("\nstate-estimate profile: " + ", ".join(label(p) for p in meta["profiles"]))
        print(
            f"\n{meta['sorties']} sorties, {meta['sim_time_s']:.1f} simulated s in "
            f"{meta['wall_s']:.1f} s wall with {meta['workers']} worker(s): "
            f"{meta['throughput_sim_s_per_s']:.1f} sortie-s per wall s\n"
            f"report: {res['out']}/report.md"
        )
    return 0
