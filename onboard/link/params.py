"""The onboard component's MAVLink parameters: every gain (``onboard/gains.py``, live) and the
runtime settings below (applied only while not flying), values REAL32. A value outside its
range is refused and the old one stays.

On MAVLink each parameter has a PX4-style id derived from its Python name
(:func:`mavlink_param_id`: ``k_a`` -> ``PRG_K_A``, ``CAM_HFOV_DEG`` -> ``PRG_CAM_HFOV``,
``TGT_DIAM_M`` -> ``PRG_TGT_DIAM``):
upper case, the component's prefix, at most 16 characters, so every ground station (MAVProxy
upper-cases what it is typed) can show and set them. Inside the code the Python names stay.

The table is saved as ``PARAM_ID = value`` TOML, written to a temporary file and renamed, so a
crash never leaves half a file; a file with the old (Python) names still loads, with a
deprecation note per name (:attr:`ParamTable.notes`), and is rewritten with the new ids on the
next change.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from ..enums import DEFAULT_LAW, GuidanceLaw, describe_codes
from ..estimation.dkf import DkfConfig
from ..gains import GAIN_SPECS, GainError, Gains, check_ranges, ranged
from .telemetry import LAW_CODES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


@dataclass(frozen=True)
class RuntimeParams:
    LAW: float = ranged(
        LAW_CODES.index(DEFAULT_LAW.value),
        "-",
        0,
        len(LAW_CODES) - 1,
        "guidance law: " + describe_codes(GuidanceLaw),
    )
    CAM_HFOV_DEG: float = ranged(90.0, "deg", 20.0, 170.0, "camera horizontal field of view")
    CAM_PITCH_DEG: float = ranged(0.0, "deg", -90.0, 90.0, "camera mount pitch, up positive")
    CAM_ROLL_DEG: float = ranged(0.0, "deg", -180.0, 180.0, "camera mount roll")
    CAM_LAT_S: float = ranged(0.0, "s", 0.0, 0.5, "OpenCV cameras: exposure-to-grab latency")
    HOVER_THR: float = ranged(1.0 / 3.0, "-", 0.05, 0.95, "normalised thrust that hovers")
    TGT_LOST_S: float = ranged(
        0.5, "s", 0.1, 5.0, "no detection this long: the track is stale (coast, re-acquire, search)"
    )
    TGT_DIAM_M: float = ranged(
        0.3, "m", 0.02, 3.0, "target (balloon) diameter: the DKF's range from apparent size"
    )
    DONE_SIZE: float = ranged(
        0.2,
        "-",
        0.01,
        1.0,
        "target lost after it grew past this fraction of the image width: the pass is done",
    )
    HOLD_SPEED: float = ranged(0.3, "m/s", 0.05, 2.0, "braking ends below this speed")

    def __post_init__(self) -> None:
        check_ranges(self, "parameter")
        if int(self.LAW) != self.LAW:
            raise GainError(
                f"parameter LAW = {self.LAW} must be a whole code: {describe_codes(GuidanceLaw)}"
            )

    @property
    def law(self) -> str:
        return LAW_CODES[int(self.LAW)]

    def dkf_config(self) -> DkfConfig:
        """The DKF settings these parameters carry (target lost timeout, target diameter)."""
        return DkfConfig(lost_timeout_s=self.TGT_LOST_S, target_diameter_m=self.TGT_DIAM_M)


def law_name(code: float | None) -> str:
    """The guidance law a ``LAW`` code names; missing (None, NaN): the parameter's default."""
    ok = code is not None and math.isfinite(code)
    return LAW_CODES[int(code if ok else RuntimeParams.LAW)]


PARAM_PREFIX = "PRG_"  # the component's parameter group, as PX4's MPC_, COM_, EKF2_


def mavlink_param_id(name: str) -> str:
    """The MAVLink id of a parameter: prefix + upper-cased Python name, a trailing unit suffix
    (``_DEG``, ``_S``, ``_M``) dropped as in PX4's names (the unit is in the metadata)."""
    return PARAM_PREFIX + re.sub(r"_(DEG|S|M)$", "", name.upper())


@dataclass(frozen=True)
class ParamSpec:
    name: str  # the Python name (gains.py, RuntimeParams)
    default: float
    minimum: float
    maximum: float
    unit: str
    meaning: str
    live: bool  # applied while flying (gains) or only on the ground
    group: str  # "Gains" or "Runtime", for ground stations' parameter trees

    @property
    def param_id(self) -> str:
        """The name on MAVLink and in params files."""
        return mavlink_param_id(self.name)


PARAM_SPECS: tuple[ParamSpec, ...] = tuple(
    ParamSpec(s.name, s.default, s.minimum, s.maximum, s.unit, s.meaning, True, "Gains")
    for s in GAIN_SPECS
) + tuple(
    ParamSpec(
        f.name,
        f.default,
        f.metadata["min"],
        f.metadata["max"],
        f.metadata["unit"],
        f.metadata["meaning"],
        False,
        "Runtime",
    )
    for f in dataclasses.fields(RuntimeParams)
)
PARAM_INDEX = {s.name: i for i, s in enumerate(PARAM_SPECS)}  # Python name -> index
PARAM_ID_INDEX = {s.param_id: i for i, s in enumerate(PARAM_SPECS)}  # MAVLink id -> index
PARAM_IDS = {s.name: s.param_id for s in PARAM_SPECS}  # Python name -> MAVLink id
PARAM_NAMES = {s.param_id: s.name for s in PARAM_SPECS}  # MAVLink id -> Python name
assert all(len(s.param_id) <= 16 and s.param_id.isupper() for s in PARAM_SPECS)
assert len(PARAM_INDEX) == len(PARAM_SPECS) == len(PARAM_ID_INDEX)


class ParamTable:
    """Current gains and runtime parameters, validated, optionally backed by a file."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self.gains = Gains()
        self.runtime = RuntimeParams()
        self.version = 0
        self.notes: list[str] = []  # deprecation notes from the last load
        if path is not None and path.exists():
            self.load(path)

    def load(self, path: Path) -> None:
        """Read ``path``; a bad file raises :class:`GainError` naming it and changes nothing."""
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError) as exc:
            raise GainError(f"{path}: cannot read: {exc}") from None
        except tomllib.TOMLDecodeError as exc:
            raise GainError(f"{path}: not valid TOML: {exc}") from None
        unknown = set(data) - set(PARAM_NAMES) - set(PARAM_INDEX)
        if unknown:
            raise GainError(f"{path}: unknown parameter(s): {', '.join(sorted(unknown))}")
        old = sorted(k for k in data if k in PARAM_INDEX and k not in PARAM_NAMES)
        renamed = {PARAM_NAMES.get(k, k) for k in data}
        if len(renamed) < len(data):
            raise GainError(f"{path}: a parameter is given under its old and its new name")
        data = {PARAM_NAMES.get(k, k): v for k, v in data.items()}
        gains = {k: v for k, v in data.items() if k in Gains.__dataclass_fields__}
        runtime = {k: v for k, v in data.items() if k in RuntimeParams.__dataclass_fields__}
        try:
            g = Gains().replace(**gains)
            r = RuntimeParams(**runtime)
        except (GainError, TypeError) as exc:
            raise GainError(f"{path}: {exc}") from None
        self.gains, self.runtime = g, r
        self.notes = [
            f"{path}: parameter name {k} is deprecated, use {PARAM_IDS[k]} "
            "(the file is rewritten with the new names on the next change)"
            for k in old
        ]

    def save(self) -> None:
        if self.path is None:
            return
        lines = ["# Peregrine onboard parameters (written by onboard run)"]
        lines += [f"{s.param_id} = {self.get(s.name)!r}" for s in PARAM_SPECS]
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
        os.replace(tmp, self.path)

    def get(self, name: str) -> float:
        if name in Gains.__dataclass_fields__:
            return float(getattr(self.gains, name))
        return float(getattr(self.runtime, name))

    def set(self, name: str, value: float, flying: bool) -> tuple[bool, str]:
        """Try to set ``name``; returns (applied, reason when not). Never raises."""
        if name not in PARAM_INDEX:
            return False, f"unknown parameter {name}"
        spec = PARAM_SPECS[PARAM_INDEX[name]]
        if flying and not spec.live:
            return False, f"{name} cannot change in flight"
        try:
            value = float(value)
            if spec.live:
                new_gains = self.gains.replace(**{name: value})
                new_runtime = self.runtime
            else:
                new_gains = self.gains
                new_runtime = dataclasses.replace(self.runtime, **{name: value})
        except (GainError, TypeError, ValueError) as exc:
            return False, str(exc)
        self.gains, self.runtime = new_gains, new_runtime
        self.version += 1
        try:
            self.save()
        except OSError as exc:
            return True, f"applied but not saved: {exc}"
        return True, ""
