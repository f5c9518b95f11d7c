"""``groundstation serve``: the operator's web app (simulator or live mode), its options and
start-up checks (a port in use, a bind error: one line, exit 2, before anything starts)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from onboard.link.address import add_host_port_option

from .cli_options import PORT, existing_file, writable_dir


def add_serve_parser(sub) -> None:
    """The ``serve`` subcommand and its options on ``sub`` (argparse's subparsers)."""
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


def run_serve(args: argparse.Namespace) -> int:
    """Serve until stopped; 2 with one line on stderr when it cannot start."""
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
