"""``groundstation sitl``: the simulator as a PX4-like vehicle over MAVLink and a camera
stream (the rig ``onboard run`` flies against), its options and start-up checks."""

from __future__ import annotations

import argparse
import sys

from .cli_options import PORT, SEED, scenario_arg, seconds
from .scenario import load_scenario, parse_overrides, with_overrides


def add_sitl_parser(sub) -> None:
    """The ``sitl`` subcommand and its options on ``sub`` (argparse's subparsers)."""
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


def run_sitl(args: argparse.Namespace) -> int:
    """Fly the SITL vehicle until stopped or ``--duration``; 2 with one line on stderr
    when it cannot start."""
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
