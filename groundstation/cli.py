"""``groundstation`` command line: run sorties, list scenarios, benchmark."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

# Only light modules here: `groundstation --help` and `scenarios` must not pay for numpy,
# filterpy/scipy, OpenCV or viser; each command imports what it needs when it runs.
from onboard.enums import DEFAULT_LAW, PAPER_LAWS, GuidanceLaw, codes
from onboard.gains import GainError

from .campaigns.tune_options import add_tune_arguments
from .cli_bench import add_bench_parser, run_bench_command
from .cli_options import (
    COUNT,
    SEED,
    SET_HELP,
    existing_file,
    scenario_arg,
    writable_dir,
)
from .cli_serve import add_serve_parser, run_serve
from .cli_sitl import add_sitl_parser, run_sitl
from .scenario import (
    CAMERA_MODES,
    ESTIMATE_PROFILES,
    ScenarioError,
    load_scenario,
    parse_overrides,
    shipped_scenarios,
    with_overrides,
)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # usage errors: exit 2 without a traceback
        self.print_usage(sys.stderr)
        self.exit(2, f"{self.prog}: error: {message}\n")


def _add_backend_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--backend", default="process", choices=("process", "ray"), help="sortie runner")
    p.add_argument(
        "--ray-address", default=None, help="Ray cluster (default: $RAY_ADDRESS, else a local Ray)"
    )


_PROFILE_HELP = (
    "state-estimate error profile for every sortie (default: each scenario's own, "
    "outdoor-gnss unless it says otherwise; ideal = ideal sensors, analysis only; "
    "docs/realism.md)"
)


def _with_profile_set(args: argparse.Namespace) -> None:
    """``--profile NAME`` is ``--set estimate.profile="NAME"`` (checked and applied alike)."""
    name = getattr(args, "profile", None)
    if name is not None:
        args.set = [*(args.set or []), f'estimate.profile="{name}"']


def _build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="groundstation", description="Peregrine ground station")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("sortie", help="run one simulated sortie to its outcome")
    s.add_argument(
        "scenario", type=scenario_arg, help="scenario TOML file, or the name of a shipped scenario"
    )
    s.add_argument("--law", default=DEFAULT_LAW.value, choices=codes(GuidanceLaw))
    s.add_argument("--seed", type=SEED, default=0)
    s.add_argument("--camera", default="projected", choices=CAMERA_MODES)
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.add_argument(
        "--log", metavar="DIR", type=writable_dir, help="record the sortie to DIR (MCAP)"
    )
    s.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help=SET_HELP)
    s.add_argument("--profile", choices=ESTIMATE_PROFILES, default=None, help=_PROFILE_HELP)

    r = sub.add_parser("replay", help="print a recorded sortie's summary")
    r.add_argument("file", type=existing_file("a sortie log (.mcap)"), help="a sortie log (.mcap)")
    r.add_argument("--json", action="store_true")

    sub.add_parser("scenarios", help="list the shipped scenarios")
    add_serve_parser(sub)
    add_sitl_parser(sub)

    c = sub.add_parser("campaign", help="reproduce one of the paper's experiments")
    c.add_argument(
        "name",
        help="static | moving | wind | outdoor | drag | size | envelope | range | agility"
        " | heldout",
    )
    c.add_argument(
        "--n", type=COUNT, default=None, help="targets / seeds / tries per cell (docs/paper.md)"
    )
    c.add_argument(
        "--laws",
        default=",".join(m.value for m in PAPER_LAWS),
        help=f"comma-separated guidance laws of {', '.join(codes(GuidanceLaw))}",
    )
    c.add_argument("--camera", default="projected", choices=CAMERA_MODES)
    c.add_argument("--seed", type=SEED, default=0)
    c.add_argument("--workers", type=COUNT, default=None, help="processes (default: cores)")
    c.add_argument("--out", type=writable_dir, help="output folder (default logs/campaigns/...)")
    c.add_argument("--json", action="store_true", help="print the aggregates as JSON")
    c.add_argument("--log", metavar="DIR", type=writable_dir, help="record every sortie to DIR")
    c.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help=SET_HELP)
    c.add_argument(
        "--only",
        action="append",
        metavar="LABEL=V1,V2",
        help="fly only the cells whose label is among the values (repeatable, all must match;"
        " e.g. agility: --only kind=turn --only value=3,5); each sortie keeps its draw and seed",
    )
    c.add_argument("--profile", choices=ESTIMATE_PROFILES, default=None, help=_PROFILE_HELP)
    _add_backend_args(c)

    t = sub.add_parser("tune", help="search gains with Optuna over a campaign (docs/tuning.md)")
    add_tune_arguments(t, SET_HELP, count=COUNT, seed=SEED, out_dir=writable_dir)
    _add_backend_args(t)

    add_bench_parser(sub)
    return p


def _cmd_sortie(args: argparse.Namespace) -> int:
    from .recording.writer import SortieRecorder
    from .sim.profiles import label
    from .sim.simulation import Simulation

    scenario = with_overrides(load_scenario(args.scenario), parse_overrides(args.set))
    rec = None if args.log is None else SortieRecorder(Path(args.log))
    sim = Simulation(
        scenario,
        args.law,
        args.seed,
        args.camera,
        keep_records=False,
        observers=[rec] if rec else (),
    )
    result = sim.run()
    if rec is not None and rec.error:
        print(f"groundstation: warning: {rec.error}", file=sys.stderr)
    if args.json:
        out = result.to_json_dict()
        if rec is not None:
            out["log"] = str(rec.path)
        print(json.dumps(out, sort_keys=True))
    else:
        r = result
        after = (
            f"recovered, lowest {r.min_alt_after_pass_m:.2f} m after the pass"
            if r.recovered
            else f"not recovered, lowest {r.min_alt_after_pass_m:.2f} m after the pass"
            if math.isfinite(r.min_alt_after_pass_m)
            else "no pass"
        )
        print(
            f"{r.scenario}: {r.outcome}  miss {r.miss_m:.3f} m (hit radius {r.hit_radius_m:.2f} m)"
            f" at t = {r.intercept_time_s:.2f} s; {after}\n"
            f"  state-estimate profile: {label(r.profile)}\n"
            f"  terminal speed {r.terminal_speed_m_s:.2f} m/s, max normal acceleration "
            f"{r.max_normal_accel_m_s2:.2f} m/s^2\n"
            f"  law {r.law}, seed {r.seed}, camera {r.camera}, detections fused "
            f"{r.detections_fused}, rejected {r.detections_rejected}"
        )
        if rec is not None:
            print(f"  recorded to {rec.path}")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from collections import Counter

    from .recording.reader import LogError, inspect_log, iter_messages, metadata_values

    path = Path(args.file)
    try:
        info = inspect_log(path)
        counts: Counter = Counter()
        events = []
        for topic, t, msg in iter_messages(path):
            counts[topic] += 1
            if topic == "/events":
                events.append({"t_s": round(t, 3), "message": msg.get("message")})
    except (LogError, OSError) as exc:
        print(f"groundstation: error: {exc}", file=sys.stderr)
        return 2
    d = info.to_json_dict()
    d["metadata"] = metadata_values(info.metadata)
    d["topics"] = dict(sorted(counts.items()))
    d["events"] = events
    if args.json:
        print(json.dumps(d, sort_keys=True))
        return 0
    miss = "—" if info.miss_m is None else f"{info.miss_m:.3f} m"
    dur = "—" if info.duration_s is None else f"{info.duration_s:.2f} s"
    print(f"{info.name}: {info.status}" + (f" ({info.problem})" if info.problem else ""))
    print(f"  {info.scenario}, law {info.law}, seed {info.seed}, camera {info.camera}")
    print(
        f"  outcome {info.outcome or 'none recorded'}, miss {miss}, duration {dur}, "
        f"{info.messages} messages"
    )
    for e in events:
        print(f"  t = {e['t_s']:7.3f} s  {e['message']}")
    return 0


def _cmd_scenarios(_: argparse.Namespace) -> int:
    for path in shipped_scenarios():
        s = load_scenario(path)
        print(f"{path.stem:26s} {s.target.motion:9s} {s.description}")
    return 0


# the commands that fly many sorties compile the kernels (onboard.jit); the others run them
# as Python and start at once
_JIT_COMMANDS = ("campaign", "tune", "bench")


def _makes_pool(args: argparse.Namespace) -> bool:
    """Does the command fly its sorties in a local process pool?"""
    if args.command in ("campaign", "tune"):
        return args.backend == "process"
    return args.command == "bench" and args.campaigns


def main(argv: Sequence[str] | None = None) -> int:
    args = _build_parser().parse_args(argv)
    if args.command in _JIT_COMMANDS:
        from onboard.jit import use_jit

        use_jit()
        if _makes_pool(args):
            from .campaigns.pool import start_pool_server

            start_pool_server(getattr(args, "workers", None))
    try:
        _with_profile_set(args)
        if args.command == "sortie":
            return _cmd_sortie(args)
        if args.command == "scenarios":
            return _cmd_scenarios(args)
        if args.command == "serve":
            return run_serve(args)
        if args.command == "replay":
            return _cmd_replay(args)
        if args.command == "sitl":
            return run_sitl(args)
        if args.command == "campaign":
            from .campaigns.definitions import CampaignError
            from .campaigns.driver import main_campaign

            try:
                return main_campaign(args)
            except CampaignError as exc:
                print(f"groundstation: error: {exc}", file=sys.stderr)
                return 2
        if args.command == "tune":
            from .campaigns.definitions import CampaignError
            from .campaigns.tune import main_tune

            try:
                return main_tune(args)
            except CampaignError as exc:  # TuneError included
                print(f"groundstation: error: {exc}", file=sys.stderr)
                return 2
        if args.command == "bench":
            return run_bench_command(args)
    except (ScenarioError, GainError) as exc:
        print(f"groundstation: error: {exc}", file=sys.stderr)
        return 2
    return 2  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
