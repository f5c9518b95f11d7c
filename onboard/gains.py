"""Every tunable gain of the onboard loop, declared once: default (the paper's flight values),
unit, allowed range and one-line meaning live in the field metadata of :class:`Gains`.

Names are at most 16 characters so that they can be MAVLink parameters.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


class GainError(ValueError):
    """A gain is unknown, not a number, or outside its allowed range."""


def ranged(default: float, unit: str, lo: float, hi: float, meaning: str) -> Any:
    """A dataclass field with its unit, allowed range and meaning (see :func:`check_ranges`)."""
    return field(default=default, metadata={"unit": unit, "min": lo, "max": hi, "meaning": meaning})


# the gains panel's groups, in the order it shows them: what each gain does
GAIN_GROUPS: tuple[str, ...] = (
    "guidance",
    "PNG FOV guard",
    "midcourse",
    "FOV hold",
    "attitude",
    "limits",
    "baselines (PG, IBVS)",
    "augmented PN",
    "APN limits",
    "disturbance and latency",
    "track loss",
    "search",
)


def _gain(default: float, unit: str, lo: float, hi: float, meaning: str, group: str) -> Any:
    """A :func:`ranged` gain with its group (one of :data:`GAIN_GROUPS`)."""
    assert group in GAIN_GROUPS, group
    return field(
        default=default,
        metadata={**ranged(default, unit, lo, hi, meaning).metadata, "group": group},
    )


def check_ranges(obj: Any, kind: str) -> None:
    """Validate every :func:`ranged` field of a frozen dataclass and store it as a float;
    anything else is a :class:`GainError` naming the field."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise GainError(f"{kind} {f.name}: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise GainError(f"{kind} {f.name}: {value} is not finite")
        lo, hi = f.metadata["min"], f.metadata["max"]
        if not lo <= value <= hi:
            unit = f.metadata["unit"]
            raise GainError(f"{kind} {f.name} = {value} is outside its range [{lo}, {hi}] {unit}")
        object.__setattr__(obj, f.name, float(value))


@dataclass(frozen=True)
class Gains:
    k_a: float = _gain(
        2.0, "m/s^2", 0.0, 10.0, "speed-ramp tangential acceleration (eq. 14)", "guidance"
    )
    K_y: float = _gain(3.0, "-", 0.0, 10.0, "PN constant, vertical plane (eq. 8)", "guidance")
    K_z: float = _gain(3.0, "-", 0.0, 10.0, "PN constant, horizontal plane (eq. 8)", "guidance")
    k_p: float = _gain(
        0.03, "rad/s/px", 0.0, 0.2, "FOV-holding yaw-rate P gain on e_x (eq. 13)", "FOV hold"
    )
    k_d: float = _gain(
        0.01, "rad/px", 0.0, 0.1, "FOV-holding yaw-rate D gain on de_x/dt (eq. 13)", "FOV hold"
    )
    k_R: float = _gain(
        8.0, "1/s", 0.5, 40.0, "attitude-error to body-rate gain (eq. 22)", "attitude"
    )
    v_max: float = _gain(12.0, "m/s", 0.5, 30.0, "cap on the desired speed (eq. 14)", "limits")
    a_max: float = _gain(
        5.0, "m/s^2", 0.5, 30.0, "saturation of the desired acceleration (eq. 17)", "limits"
    )
    omega_max: float = _gain(
        4.0, "rad/s", 0.1, 10.0, "body-rate command norm limit (eq. 24)", "limits"
    )
    # 1 m/s, not less: below it a GNSS-grade velocity estimate (0.1-0.2 m/s a component) does
    # not know the velocity's direction, and PN would turn that noise into the flight path
    v_min: float = _gain(
        1.0, "m/s", 0.05, 5.0, "below this speed fly along the LOS (no PNG)", "guidance"
    )
    k_brake: float = _gain(
        1.0, "1/s", 0.1, 5.0, "velocity gain when holding (no/lost target)", "track loss"
    )
    k_brake_z: float = _gain(
        3.0,
        "1/s",
        0.1,
        10.0,
        "braking: vertical velocity gain (a descent is stopped first)",
        "track loss",
    )
    k_selfcal: float = _gain(
        1.0,
        "-",
        0.0,
        1.0,
        "1: estimate the target's size and the camera-IMU time offset in flight and use them",
        "disturbance and latency",
    )
    k_v: float = _gain(
        1.8,
        "1/s",
        0.2,
        200.0,
        "PG/IBVS baselines: velocity-loop gain (PX4's; 1/dt = eq. 17)",
        "baselines (PG, IBVS)",
    )
    k_ibvs: float = _gain(
        1.0,
        "-",
        0.0,
        10.0,
        "IBVS baseline: image-error decay per unit closing",
        "baselines (PG, IBVS)",
    )
    k_dob: float = _gain(
        2.0,
        "1/s",
        0.0,
        10.0,
        "disturbance-observer bandwidth, feed-forward -d^ (0: off)",
        "disturbance and latency",
    )
    k_drag: float = _gain(
        0.17,
        "1/s",
        0.0,
        2.0,
        "airframe drag per mass in the observer model (EKF2_MCOEF)",
        "disturbance and latency",
    )
    fov_margin: float = _gain(
        8.0,
        "deg",
        0.0,
        30.0,
        "PNG FOV guard: keep the LOS this far inside top/bottom (0 = off)",
        "PNG FOV guard",
    )
    pur_zone: float = _gain(
        15.0,
        "deg",
        0.0,
        40.0,
        "PNG pursuit bias: acts within this of the top/bottom (0 = off)",
        "PNG FOV guard",
    )
    k_pur: float = _gain(
        4.0, "1/s", 0.0, 20.0, "PNG pursuit bias: heading-to-LOS rate at the edge", "PNG FOV guard"
    )
    tau_los: float = _gain(
        0.0, "s", 0.0, 2.0, "low-pass time constant on the LOS change (0 = off)", "midcourse"
    )
    # latency compensation (docs/simulation.md, "The state-estimate model"): the runtime
    # already carries PX4's stamped attitude to the tick (fc_state.state_at), so t_att_lag is
    # for an unstamped attitude only; the velocity it uses unstamped, LOCAL_POSITION_NED
    # ~20 ms old (EKF2's output predictor, the 100 Hz stream and the link: the estimate
    # model's lag_s)
    t_att_lag: float = _gain(
        0.0,
        "s",
        0.0,
        0.1,
        "attitude-estimate latency, predicted away with the gyro (0 = off)",
        "disturbance and latency",
    )
    t_vel_lag: float = _gain(
        0.02,
        "s",
        0.0,
        0.1,
        "velocity-estimate latency, predicted with the thrust model (0 = off)",
        "disturbance and latency",
    )
    tau_vel: float = _gain(
        3.0,
        "s",
        0.0,
        10.0,
        "own-velocity complementary filter time constant (0 = off)",
        "disturbance and latency",
    )
    tau_zem: float = _gain(
        1.5,
        "s",
        0.0,
        10.0,
        "PNG midcourse: time constant nulling the ZEM far away (0 = off)",
        "midcourse",
    )
    r_mid: float = _gain(
        40.0,
        "m",
        5.0,
        1000.0,
        "PNG midcourse: acts beyond this range, fully beyond twice it",
        "midcourse",
    )
    # track loss, re-acquisition and search (onboard/control/reacquire.py; docs/core.md)
    t_coast: float = _gain(
        1.0,
        "s",
        0.0,
        5.0,
        "track stale (PRG_TGT_LOST): fly the law on the DKF prediction this long",
        "track loss",
    )
    coast_std: float = _gain(
        40.0,
        "px",
        1.0,
        500.0,
        "coast only while the predicted image point's 1 sigma is below",
        "track loss",
    )
    t_reacq: float = _gain(
        3.0,
        "s",
        0.0,
        20.0,
        "after the coast: yaw to the predicted LOS and slow down this long",
        "track loss",
    )
    v_reacq: float = _gain(
        1.0, "m/s", 0.0, 10.0, "re-acquisition: speed along the predicted LOS", "track loss"
    )
    n_confirm: float = _gain(
        3.0,
        "-",
        1.0,
        20.0,
        "detections that confirm a track: the first, or one off the prediction",
        "track loss",
    )
    conf_deg: float = _gain(
        3.0,
        "deg",
        0.1,
        30.0,
        "consistency gate between detections (+3 sigma of the prediction)",
        "track loss",
    )
    t_wait: float = _gain(
        0.5,
        "s",
        0.0,
        10.0,
        "no detection since the start this long: search (hold until then)",
        "search",
    )
    t_search: float = _gain(
        60.0,
        "s",
        0.0,
        300.0,
        "search this long, then the failsafe (brake and hold)",
        "search",
    )
    w_search: float = _gain(0.6, "rad/s", 0.0, 3.0, "search at hover: yaw-scan rate", "search")
    v_search: float = _gain(
        8.0,
        "m/s",
        0.0,
        20.0,
        "search when moving at its start: speed along that course (the cue)",
        "search",
    )
    weave_deg: float = _gain(
        40.0,
        "deg",
        0.0,
        60.0,
        "search along a course: yaw-weave amplitude about it (0 = off)",
        "search",
    )
    t_weave: float = _gain(3.0, "s", 0.5, 60.0, "search along a course: yaw-weave period", "search")
    t_carry: float = _gain(
        5.0,
        "s",
        0.0,
        30.0,
        "re-acquired track keeps the old depth/velocity if lost < this (0=off)",
        "track loss",
    )
    h_floor: float = _gain(
        2.0,
        "m",
        0.0,
        100.0,
        "coast/re-acquire/search: never descend below this height above home",
        "limits",
    )

    # ground clearance near a low target (onboard/control/clearance.py)
    # 1 m: twice the altitude error of a GNSS/barometer estimate (sigma up to 0.5 m); a
    # vehicle that knows its height to centimetres (motion capture, a rangefinder) sets less
    h_clear: float = _gain(
        1.0,
        "m",
        0.0,
        100.0,
        "low targets: stop a descent this high above home (approach speed, recovery)",
        "limits",
    )
    k_up: float = _gain(
        0.5,
        "-",
        0.0,
        1.0,
        "low targets: part of the believed airframe's upward accel (TW-1)g used (0 = off)",
        "limits",
    )
    t_up_lag: float = _gain(
        0.25,
        "s",
        0.0,
        2.0,
        "low targets: response lag before an upward command acts on the descent",
        "limits",
    )

    v_tgt_sink: float = _gain(
        1.0,
        "m/s",
        0.0,
        20.0,
        "low targets: fastest sink of the target assumed between range estimates",
        "limits",
    )

    # the augmented law's command limit from the airframe (onboard/control/apn.py)
    tilt_max: float = _gain(
        45.0,
        "deg",
        10.0,
        80.0,
        "APN: the airframe's tilt limit (PX4 MPC_TILTMAX_AIR), caps its lateral accel",
        "APN limits",
    )
    tilt_end: float = _gain(
        70.0,
        "deg",
        10.0,
        80.0,
        "APN: tilt allowed in the endgame (time to go under t_end), caps its lateral accel",
        "APN limits",
    )
    t_end: float = _gain(
        1.0,
        "s",
        0.0,
        5.0,
        "APN: the endgame's time to go, in which tilt_end replaces tilt_max",
        "APN limits",
    )
    z_off: float = _gain(
        1.0,
        "-",
        0.0,
        10.0,
        "APN: the target's acceleration within this many sigmas of its estimate is not flown",
        "augmented PN",
    )
    z_full: float = _gain(
        2.0,
        "-",
        0.0,
        20.0,
        "APN: the target's acceleration is flown whole from this many sigmas on",
        "augmented PN",
    )
    a_z_margin: float = _gain(
        2.0,
        "m/s^2",
        0.0,
        10.0,
        "APN: vertical acceleration kept in reserve from the thrust",
        "APN limits",
    )
    t_turn: float = _gain(
        0.0,
        "s",
        0.0,
        5.0,
        "APN: predict the target's accel turning at its turn rate over min(t_go, this) (0=off)",
        "augmented PN",
    )
    k_turn_v: float = _gain(
        0.0,
        "-",
        0.0,
        5.0,
        "APN: speed cap, this x the speed whose tightest turn is the target's turn (0=off)",
        "augmented PN",
    )
    v_end: float = _gain(
        4.0, "m/s", 0.0, 30.0, "APN: cap within r_end: target's speed + this", "APN limits"
    )
    r_end: float = _gain(
        20.0, "m", 0.0, 100.0, "APN: range within which the speed cap v_end holds", "APN limits"
    )

    def __post_init__(self) -> None:
        check_ranges(self, "gain")

    def replace(self, **changes: float) -> Gains:
        """A validated copy with some gains changed; unknown names raise :class:`GainError`."""
        unknown = set(changes) - set(GAIN_NAMES)
        if unknown:
            raise GainError(f"unknown gain(s): {', '.join(sorted(unknown))}")
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "gains") -> Gains:
        """Defaults overridden by ``values``; errors name the gain and the source."""
        try:
            return cls().replace(**dict(values))
        except GainError as exc:
            raise GainError(f"{source}: {exc}") from None

    def to_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    @functools.cached_property
    def packed(self) -> Any:
        """:func:`pack_gains` of these gains, made once per gains object (they are frozen)."""
        return pack_gains(self)


@dataclass(frozen=True)
class GainSpec:
    name: str
    default: float
    unit: str
    minimum: float
    maximum: float
    meaning: str
    group: str


GAIN_SPECS: tuple[GainSpec, ...] = tuple(
    GainSpec(
        f.name, f.default, *(f.metadata[k] for k in ("unit", "min", "max", "meaning", "group"))
    )
    for f in dataclasses.fields(Gains)
)
GAIN_NAMES: tuple[str, ...] = tuple(s.name for s in GAIN_SPECS)
assert all(len(n) <= 16 for n in GAIN_NAMES)


def load_gains_file(path: str | Path) -> Gains:
    """Gains from a TOML file of ``name = value`` lines; errors name the gain and the file."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise GainError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise GainError(f"{path}: not valid TOML: {exc}") from None
    return Gains.from_mapping(data, source=str(path))


GainIndex = enum.IntEnum("GainIndex", [(name, i) for i, name in enumerate(GAIN_NAMES)])
GainIndex.__doc__ = """Index of each gain in :func:`pack_gains`'s array (``G[GainIndex.K_y]``
in a kernel): the declaration's order, so there is no second list of the gains to keep."""


def pack_gains(gains: Gains) -> Any:
    """Every gain as one float64 array in :class:`Gains`'s declaration order (the units of the
    declaration: degrees stay degrees), for the compiled kernels, which cannot read a
    dataclass. Index it with :class:`GainIndex`."""
    import numpy as np  # not at import: ``--help`` and ``scenarios`` read the gains without it

    return np.array([getattr(gains, name) for name in GAIN_NAMES], dtype=np.float64)
