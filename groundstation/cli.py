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
from onboard.enums import PAPER_LAWS, GuidanceLaw, codes
from onboard.gains import GainError
from onboard.link.address import add_host_port_option

from .campaigns.tune_options import add_tune_arguments
from .cli_bench import add_bench_parser, run_bench_command
from .cli_options import (
    COUNT,
    PORT,
    SEED,
    SET_HELP,
    existing_file,
    scenario_arg,
    seconds,
    writable_dir,
)
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
    s.add_argument("--law", default=GuidanceLaw.PNG.value, choices=codes(GuidanceLaw))
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

    sv = sub.add_parser("serve", help="start the operator's web app (simulator mode)")
    sv.add_argument(
        "--sim",
        action="store_true",
        default=True,
        help="simulator mode (the default unless --mavlink is given)",
    )
    sv.add_argument("--host", default="127.0.0.1", help="address to listen on")
    sv.add_argument("--port", type=PORT, default=8000, help="0: any free port")
    sv.add_argument(
        "--scene-port",
        type=PORT,
        default=0,
        help="the 3D view's own port on the same address (default 0: any free port)",
    )
    sv.add_argument(
        "--no-auth",
        action="store_true",
        help="no access token (refused unless the host is a loopback address)",
    )
    sv.add_argument(
        "--data-dir",
        type=writable_dir,
        help="where named gain sets are kept (default ~/.peregrine)",
    )

    sv.add_argument(
        "--mavlink",
        metavar="URL",
        default=None,
        help="live mode: the onboard computer's ground link (e.g. udpin:127.0.0.1:14550)",
    )
    sv.add_argument(
        "--signing-key",
        metavar="FILE",
        type=existing_file("a file of 64 hex digits"),
        help="MAVLink 2 signing key (live mode)",
    )
    sv.add_argument(
        "--log-dir",
        type=writable_dir,
        default="logs",
        help="where sorties are recorded (default logs)",
    )
    add_host_port_option(
        sv,
        "--foxglove",
        8765,
        "also publish every sortie's channels (the recording's) to Foxglove over its "
        "WebSocket protocol on HOST:PORT (alone: 127.0.0.1:8765; a bare PORT is on "
        "127.0.0.1); in Foxglove: Open connection, Foxglove WebSocket, ws://HOST:PORT",
    )
    add_host_port_option(
        sv,
        "--video",
        5600,
        "live mode: show the vehicle's H.264/RTP video (onboard run --video) in the "
        "image panel, received on UDP HOST:PORT (alone: 127.0.0.1:5600)",
    )

    st = sub.add_parser("sitl", help="run the simulator as a PX4-like vehicle over MAVLink")
    st.add_argument(
        "scenario",
        nargs="?",
        default="cv-top-to-bottom",
        type=scenario_arg,
        help="scenario TOML file or shipped name (default cv-top-to-bottom)",
    )
    st.add_argument(
        "--mavlink",
        metavar="URL",
        default=None,
        help="pymavlink connection string (default udpout:127.0.0.1:14540, PX4's)",
    )
    st.add_argument(
        "--camera-port",
        type=PORT,
        default=5600,
        help="TCP port of the camera stream on 127.0.0.1 (0: any free port)",
    )
    st.add_argument("--seed", type=SEED, default=0)
    st.add_argument(
        "--set",
        action="append",
        metavar="SECTION.KEY=VALUE",
        help="change one scenario value, as for sorties: --set estimate.enabled=false (ideal "
        "sensors), --set camera.false_probability=0.05 (detector faults)",
    )
    st.add_argument("--duration", type=seconds(0, False), help="stop after this many seconds")
    st.add_argument(
        "--on-ground",
        action="store_true",
        help="start disarmed and landed below the scenario's start (arm, then takeoff)",
    )
    st.add_argument(
        "--home",
        metavar="LAT,LON,ALT",
        default=None,
        help="home: latitude, longitude (deg), altitude AMSL (m) of local (0, 0, 0) "
        "(default PX4 SITL's, 47.397742,8.545594,488)",
    )
    st.add_argument(
        "--offboard-loss",
        type=seconds(0, False),
        default=1.0,
        help="PX4 COM_OF_LOSS_T: seconds without setpoints before HOLD",
    )
    st.add_argument(
        "--camera-blackout-after",
        type=seconds(0, True),
        default=None,
        metavar="S",
        help="fault injection: no camera frames after S s of sortie time",
    )

    c = sub.add_parser("campaign", help="reproduce one of the paper's experiments")
    c.add_argument(
        "name", help="static | moving | wind | outdoor | drag | size | envelope | range | agility"
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


def _port_problem(host: str, port: int) -> str | None:
    """Why ``serve`` could not listen on host:port, or None (checked before anything
    starts, so a port in use prints no URL)."""
    import errno

    from onboard.link.address import bind_tcp_listener

    try:
        bind_tcp_listener(host, port).close()
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            return (
                f"argument --port: port {port} on {host} is in use (another ground "
                "station?); pick another with --port N, or --port 0 for any free port"
            )
        return f"argument --host: cannot listen on {host}:{port}: {exc.strerror or exc}"
    return None


def _cmd_serve(args: argparse.Namespace) -> int:
    from onboard.link.px4 import LinkError, load_signing_key

    from .app.server import GroundStation

    problem = _port_problem(args.host, args.port)
    if problem is not None:
        print(f"groundstation serve: error: {problem}", file=sys.stderr)
        return 2
    foxglove = None
    if args.foxglove is not None:
        from onboard.channels.live import FoxgloveLive

        try:
            foxglove = FoxgloveLive(port=args.foxglove[1], host=args.foxglove[0])
        except Exception as exc:  # the SDK's bind error: one clear line
            print(
                f"groundstation serve: error: argument --foxglove: cannot listen on "
                f"{args.foxglove[0]}:{args.foxglove[1]}: {exc}",
                file=sys.stderr,
            )
            return 2
    try:
        key = load_signing_key(args.signing_key) if args.signing_key else None
        gs = GroundStation(
            args.host,
            args.port,
            args.no_auth,
            Path(args.data_dir) if args.data_dir else None,
            log_dir=Path(args.log_dir),
            mavlink_url=args.mavlink,
            signing_key=key,
            foxglove=foxglove,
            video=args.video,
            scene_port=args.scene_port,
        )
    except (ValueError, LinkError, OSError) as exc:
        if foxglove is not None:
            foxglove.stop()
        print(f"groundstation: error: {exc}", file=sys.stderr)
        return 2
    mode = f"live on {args.mavlink}" if args.mavlink else "simulator mode"
    print(f"Peregrine ground station ({mode}): open {gs.url()}", flush=True)
    if foxglove is not None:
        print(f"Foxglove live: open connection {foxglove.url()}", flush=True)
    gs.run_forever()
    return 0


def _cmd_sitl(args: argparse.Namespace) -> int:
    import signal

    from onboard.link.px4 import DEFAULT_SITL_URL, LinkError, MavLink

    from .sitl.autopilot import Home
    from .sitl.camera_server import CameraServer
    from .sitl.vehicle import SitlOptions, SitlVehicle

    scenario = with_overrides(load_scenario(args.scenario), parse_overrides(args.set))
    try:
        home = Home()
        if args.home:
            lat, lon, alt = (float(c) for c in args.home.split(","))
            home = Home(lat, lon, alt)
    except ValueError as exc:
        print(f"groundstation: error: --home {args.home}: {exc}", file=sys.stderr)
        return 2
    if not 0.0 <= args.offboard_loss <= 60.0:  # PX4's COM_OF_LOSS_T range
        print(f"groundstation: error: --offboard-loss {args.offboard_loss}: expected 0 to 60 s",
              file=sys.stderr)  # fmt: skip
        return 2
    try:
        link = MavLink(args.mavlink or DEFAULT_SITL_URL, 1, 1)
        camera = CameraServer("127.0.0.1", args.camera_port)
    except (LinkError, OSError) as exc:
        print(f"groundstation: error: {exc}", file=sys.stderr)
        return 2
    vehicle = SitlVehicle(
        scenario,
        link,
        camera,
        SitlOptions(
            args.offboard_loss, args.camera_blackout_after, args.seed, home, args.on_ground
        ),
    )
    signal.signal(signal.SIGTERM, lambda *_: vehicle.stop())
    try:
        vehicle.run(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        camera.close()
        link.close()
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
            return _cmd_serve(args)
        if args.command == "replay":
            return _cmd_replay(args)
        if args.command == "sitl":
            return _cmd_sitl(args)
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
