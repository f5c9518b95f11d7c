"""``onboard`` command line. Today: inspect and check gains; the MAVLink runtime
(``onboard run``) comes with the vehicle integration."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from .gains import GAIN_SPECS, GainError, Gains

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def load_gains_file(path: str | Path) -> Gains:
    """Gains from a TOML file of ``name = value`` lines; errors name the gain and the file."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise GainError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise GainError(f"{path}: not valid TOML: {exc}") from None
    return Gains.from_mapping(data, source=str(path))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="onboard", description="Peregrine onboard loop")
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser("gains", help="list every gain (default, unit, range, meaning)")
    g.add_argument("--check", metavar="FILE", help="validate a gains TOML file and print it")
    args = parser.parse_args(argv)
    if args.command == "gains":
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
            print(
                f"{s.name:10s} {values[s.name]:8g} {s.default:8g} {s.unit:9s} {rng:16s} {s.meaning}"
            )
        return 0
    return 2  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
