"""The ``groundstation`` command line's option checks. Each returns an argparse ``type``: a
bad value becomes "argument --OPT: <what is allowed>, got X" and exit status 2, before any work
starts. Light: no numpy here (``groundstation --help`` must not pay for it)."""

from __future__ import annotations

import argparse
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

from .scenario import SCENARIO_DIR, shipped_scenarios


def int_at_least(lo: int, hi: int | None = None, note: str = "") -> Callable[[str], int]:
    allowed = f"an integer >= {lo}" if hi is None else f"an integer from {lo} to {hi}"
    allowed += note

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text!r}") from None
        if value < lo or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {value}")
        return value

    return parse


def seconds(minimum: float, inclusive: bool) -> Callable[[str], float]:
    allowed = f"a number of seconds {'>=' if inclusive else '>'} {minimum:g}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text!r}") from None
        if not math.isfinite(value) or value < minimum or (value == minimum and not inclusive):
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text}")
        return value

    return parse


def existing_file(what: str) -> Callable[[str], str]:
    def parse(text: str) -> str:
        p = Path(text)
        if p.is_dir():
            raise argparse.ArgumentTypeError(f"{text} is a folder; give {what}")
        if not p.is_file():
            raise argparse.ArgumentTypeError(f"{text}: no such file; give {what}")
        if not os.access(p, os.R_OK):
            raise argparse.ArgumentTypeError(f"{text}: not readable; give {what}")
        return text

    return parse


def scenario_arg(text: str) -> str:
    p = Path(text)
    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; give a scenario TOML file or name")
    if not p.exists() and not (not p.suffix and (SCENARIO_DIR / f"{p.name}.toml").is_file()):
        names = ", ".join(q.stem for q in shipped_scenarios())
        raise argparse.ArgumentTypeError(
            f"{text}: no such file or shipped scenario (shipped: {names})"
        )
    return text


def writable_dir(text: str) -> str:
    """A folder that is, or can be created, writable: the nearest existing ancestor decides."""
    p = Path(text)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a file; give a folder (it is created)")
    probe = p.absolute()
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: {probe} is a file; give a folder")
    try:  # a real write: os.access says yes to root even on /proc or a read-only disk
        os.rmdir(tempfile.mkdtemp(prefix=".peregrine-probe-", dir=probe))
    except OSError as exc:
        raise argparse.ArgumentTypeError(
            f"{text}: cannot write in {probe} ({exc.strerror or exc}); give a writable folder"
        ) from None
    return text


PORT = int_at_least(0, 65535, " (0: any free port)")
SEED = int_at_least(0)


COUNT = int_at_least(1)


SET_HELP = (
    "change one scenario value for every sortie (repeatable), e.g. --set camera.delay_s=0 "
    "--set gains.k_v=100"
)
