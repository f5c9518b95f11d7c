"""``onboard`` command line: inspect and check gains, and run the loop on the vehicle."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence
from pathlib import Path

from .gains import GAIN_SPECS, GainError, Gains, load_gains_file
from .link.address import add_host_port_option


def _positive(unit: str, maximum: float = float("inf")):
    """An argparse type: a finite number > 0 (and <= maximum); otherwise exit 2 naming it."""
    allowed = f"a number of {unit} > 0" + (
        "" if maximum == float("inf") else f" and <= {maximum:g}"
    )

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text!r}") from None
        if not 0.0 < value <= maximum:  # NaN fails too
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text}")
        return value

    return parse


def _gains(args) -> int:
    values = Gains().to_dict()
    if args.check:
        try:
            values = load_gains_file(args.check).to_dict()
        except GainError as exc:
            print(f"onboard: error: {exc}", file=sys.stderr)
            return 2
    print(f"{'name':10s} {'value':>8s} {'default':>8s} {'unit':9s} {'range':16s} meaning")
    for s in GAIN_SPECS:
        rng = f"[{s.minimum:g}, {s.maximum:g}]"
        print(f"{s.name:10s} {values[s.name]:8g} {s.default:8g} {s.unit:9s} {rng:16s} {s.meaning}")
    return 0


def _run(args) -> int:
    from .link.px4 import LinkError, load_signing_key
    from .runtime.runner import OnboardRuntime, RuntimeConfig
    from .runtime.video import VideoConfig

    try:
        video = None
        if args.video is not None:
            video = VideoConfig(
                host=args.video[0],
                port=args.video[1],
                fps=args.video_fps,
                kbps=round(args.video_kbps),
                overlay=args.video_overlay == "on",
            )
        key = load_signing_key(args.signing_key) if args.signing_key else None
        if args.sitl_auto_start and not args.camera.startswith("sitl://"):
            raise LinkError("--sitl-auto-start is only allowed with a sitl:// camera")
        config = RuntimeConfig(
            fc_url=args.mavlink,
            camera=args.camera,
            gcs_url=args.gcs or None,
            params_path=Path(args.params) if args.params else None,
            control_rate_hz=args.rate,
            signing_key=key,
            auto_start=args.sitl_auto_start,
            stats_path=Path(args.stats) if args.stats else None,
            log_dir=Path(args.log) if args.log else None,
            realtime_priority=args.realtime,
            lock_memory=args.lock_memory == "on",
            cpu=args.cpu,
            inject_delays_seed=args.inject_delays,
            video=video,
            foxglove=args.foxglove,
        )
        if not 10.0 <= args.rate <= 1000.0:
            raise LinkError(f"--rate {args.rate}: expected 10 to 1000 Hz")
        runtime = OnboardRuntime(config)
    except (GainError, LinkError, OSError, ValueError) as exc:
        print(f"onboard: error: {exc}", file=sys.stderr)
        return 2
    if key is None and config.gcs_url:
        print(
            "onboard: warning: no --signing-key: anyone on the ground link may command the vehicle",
            file=sys.stderr,
        )
    signal.signal(signal.SIGTERM, lambda *_: runtime.stop())
    return runtime.run(args.duration)


def _priority(text: str) -> int | None:
    """``--realtime``: a SCHED_FIFO priority of 1 to 99, or ``off`` (None)."""
    if text == "off":
        return None
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 99:
        raise argparse.ArgumentTypeError(f"expected a priority of 1 to 99 or off, got {text!r}")
    return value


def _check_rt(args) -> int:
    from .runtime.check_rt import report

    return report(args.seconds, args.priority)


def main(argv: Sequence[str] | None = None) -> int:
    from .link.px4 import DEFAULT_GCS_URL, DEFAULT_ONBOARD_FC_URL
    from .runtime.realtime import DEFAULT_PRIORITY

    parser = argparse.ArgumentParser(prog="onboard", description="Peregrine onboard loop")
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser("gains", help="list every gain (default, unit, range, meaning)")
    g.add_argument("--check", metavar="FILE", help="validate a gains TOML file and print it")
    r = sub.add_parser("run", help="fly: the interception loop against PX4 over MAVLink")
    r.add_argument(
        "--mavlink",
        default=DEFAULT_ONBOARD_FC_URL,
        metavar="URL",
        help="flight controller: pymavlink connection string (serial device with "
        "baud as /dev/ttyTHS1,921600, udpin:, udpout:, tcp:); default %(default)s",
    )
    r.add_argument(
        "--camera",
        required=True,
        metavar="SOURCE",
        help="OpenCV source (device index, /dev/videoN, GStreamer pipeline, video "
        "file) or sitl://HOST:PORT",
    )
    r.add_argument(
        "--gcs",
        default=DEFAULT_GCS_URL,
        metavar="URL",
        help="ground link for telemetry, parameters and commands (default "
        "%(default)s; '' for none)",
    )
    r.add_argument(
        "--params",
        metavar="FILE",
        help="parameter file (TOML), read at start and rewritten on every change",
    )
    r.add_argument(
        "--rate", type=_positive("Hz", 1000.0), default=200.0, help="control rate, Hz (default 200)"
    )
    r.add_argument(
        "--signing-key",
        metavar="FILE",
        help="MAVLink 2 signing key (64 hex digits): the ground link then accepts "
        "only signed parameters and commands",
    )
    r.add_argument(
        "--sitl-auto-start",
        action="store_true",
        help="SITL only: start the intercept as soon as the target is in view",
    )
    r.add_argument("--duration", type=_positive("seconds"), help="stop after this many seconds")
    r.add_argument("--stats", metavar="FILE", help="write timing figures (JSON) here at exit")
    r.add_argument(
        "--realtime",
        type=_priority,
        default=DEFAULT_PRIORITY,
        metavar="PRIO|off",
        help="run the control thread under SCHED_FIFO at this priority (1-99; default "
        "%(default)s; off: normal scheduling). Without the permission (LimitRTPRIO, "
        "CAP_SYS_NICE) one warning line and normal scheduling",
    )
    r.add_argument(
        "--lock-memory",
        choices=("on", "off"),
        default="on",
        help="mlockall while the loop runs, so no tick waits for a page (default on; needs "
        "LimitMEMLOCK=infinity or CAP_IPC_LOCK, else one warning line)",
    )
    r.add_argument(
        "--cpu",
        type=int,
        metavar="N",
        help="bind the control thread to CPU N (default: to the isolated CPUs, isolcpus=, "
        "when there are any)",
    )
    r.add_argument(
        "--inject-delays",
        type=int,
        metavar="SEED",
        help="fault injection (testing only): delay the control thread's wake-ups, p99 5 ms, "
        "a 30 ms stall each second and one 150 ms freeze 4 s in, seeded",
    )
    r.add_argument(
        "--log",
        metavar="DIR",
        help="record every MAVLink frame in and out to DIR/<UTC>_onboard.tlog",
    )
    add_host_port_option(
        r,
        "--video",
        5600,
        "stream the camera as H.264 over RTP/UDP to HOST:PORT (alone: 127.0.0.1:5600, "
        "what QGroundControl's UDP h.264 video and groundstation serve --video receive)",
    )
    add_host_port_option(
        r,
        "--foxglove",
        8765,
        "publish the recording's channels over Foxglove's WebSocket protocol on "
        "HOST:PORT (alone: 127.0.0.1:8765, loopback; open it in Foxglove as a Foxglove "
        "WebSocket connection)",
    )
    r.add_argument(
        "--video-overlay",
        choices=("on", "off"),
        default="on",
        help="draw the detection and the DKF estimate on the video (default on)",
    )
    r.add_argument(
        "--video-fps", type=_positive("frames/s", 120.0), default=30.0, help="default 30"
    )
    r.add_argument(
        "--video-kbps", type=_positive("kbit/s", 50000.0), default=2000.0, help="default 2000"
    )
    c = sub.add_parser("check-rt", help="what this computer offers a real-time control loop")
    c.add_argument(
        "--seconds",
        type=_positive("seconds", 600.0),
        default=10.0,
        help="how long to measure the wake-up latency of a 5 ms periodic sleep (default 10)",
    )
    c.add_argument(
        "--priority",
        type=_priority,
        default=DEFAULT_PRIORITY,
        metavar="PRIO|off",
        help="measure under SCHED_FIFO at this priority when permitted, as onboard run "
        "--realtime would (default %(default)s)",
    )
    args = parser.parse_args(argv)
    if args.command == "check-rt":
        return _check_rt(args)
    if args.command == "gains":
        return _gains(args)
    if args.command == "run":
        return _run(args)
    return 2  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
