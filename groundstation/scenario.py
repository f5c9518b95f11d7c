"""Scenario files (TOML): strict loading into typed dataclasses.

Every section is a dataclass below; its fields are the allowed keys, fields without a default
are required, and the annotation gives the type. An unknown key, a missing required key, a
wrong type or an impossible value raises :class:`ScenarioError` naming the file and the key.
Angles are degrees in the file and stay so named (``yaw_deg``); they are converted where used.
"""

from __future__ import annotations

import dataclasses
import math
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from onboard.constants import GRAVITY_M_S2
from onboard.gains import GainError, Gains

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

Vec3 = tuple[float, float, float]
MOTIONS = ("static", "cv", "ca", "sinusoid", "circle", "escape", "takeoff", "tethered")
SCENARIO_DIR = Path(__file__).parent / "scenarios"


CAMERA_MODES = ("projected", "rendered")  # how the simulated camera sees the target


@dataclass(frozen=True)
class ScenarioProblem:
    """One thing wrong with a scenario: the dotted key (``target.motion``; ``None`` for a
    syntax error), what is wrong, and where in the file (1-based line and column, ``None``
    where the key is not in the file, e.g. a missing key or a ``--set`` value)."""

    key: str | None
    message: str
    line: int | None = None
    column: int | None = None

    def __str__(self) -> str:
        where = "" if self.line is None else f"line {self.line}: "
        if self.line is not None and self.column is not None:
            where = f"line {self.line}, column {self.column}: "
        return where + self.message

    def to_json_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


class ScenarioError(ValueError):
    """A scenario file is malformed. It carries every problem found (:attr:`problems`, each
    with its key and line); the message has one line per problem, each naming the file."""

    def __init__(
        self,
        message: str | None = None,
        *,
        source: str = "<memory>",
        problems: Sequence[ScenarioProblem] = (),
    ) -> None:
        self.source = source
        self.problems: list[ScenarioProblem] = list(problems) or [
            ScenarioProblem(None, message or "invalid scenario")
        ]
        if message is None:
            message = "\n".join(f"{source}: {p}" for p in self.problems)
        super().__init__(message)

    def to_json_dict(self) -> dict[str, Any]:
        """The structured error the API and the dashboard receive."""
        return {
            "detail": str(self),
            "source": self.source,
            "problems": [p.to_json_dict() for p in self.problems],
        }


@dataclass(frozen=True)
class InterceptorSpec:
    position_m: Vec3
    velocity_m_s: Vec3 = (0.0, 0.0, 0.0)
    yaw_deg: float = 90.0  # heading of body x from +x toward +y
    size_m: float = 0.3  # diameter used for the hit test
    mass_kg: float = 1.5
    thrust_to_weight: float = 3.0
    drag_n_s_m: float = 0.25  # linear drag on air-relative velocity
    rate_time_constant_s: float = 0.05
    thrust_time_constant_s: float = 0.03
    max_rate_deg_s: float = 229.18  # 4 rad/s


@dataclass(frozen=True)
class TargetSpec:
    motion: str
    position_m: Vec3  # start position (tethered: rest position)
    velocity_m_s: Vec3 = (0.0, 0.0, 0.0)  # cv, ca, sinusoid drift, escape start, takeoff climb
    acceleration_m_s2: Vec3 = (0.0, 0.0, 0.0)  # ca, escape
    amplitude_m: Vec3 = (0.0, 0.0, 0.0)  # sinusoid
    period_s: float = 0.0  # sinusoid, circle (negative: clockwise circle)
    radius_m: float = 0.0  # circle
    max_speed_m_s: float = 30.0  # escape
    start_s: float = 0.0  # takeoff: climb starts at this time
    diameter_m: float = 0.3
    tether_length_m: float = 1.0  # tethered
    net_lift_n: float = 0.0  # tethered: buoyancy minus weight; 0 = from helium physics
    mass_kg: float = 0.0  # tethered: balloon, gas and added air mass; 0 = from physics
    envelope_mass_kg: float = 0.0015  # tethered: the latex (a ~0.16 m party balloon)
    drag_coefficient: float = 0.47  # tethered: sphere


@dataclass(frozen=True)
class CameraSpec:
    width_px: int = 640
    height_px: int = 480
    hfov_deg: float = 90.0
    rate_hz: float = 30.0
    delay_s: float = 0.08  # capture to result
    delay_jitter_s: float = 0.005  # 1 sigma
    noise_px: float = 1.0  # 1 sigma, projected mode
    dropout_probability: float = 0.02
    mount_pitch_deg: float = 0.0
    mount_roll_deg: float = 0.0
    # detector realism (README "Detector realism"); each 0 switches its part off
    min_blob_px: float = 0.0  # blobs narrower than this (diameter, px) are not detected
    false_probability: float = 0.0  # per frame: a false red blob (clutter) is detected
    false_blob_px: float = 5.0  # diameter of a false blob; the larger blob wins the frame
    burst_probability: float = 0.0  # per frame: a good frame starts a drop burst
    burst_mean_frames: float = 5.0  # mean burst length (frames), geometric
    burst_drop_probability: float = 1.0  # drop probability inside a burst


WIND_MODELS = ("uniform", "jet")  # groundstation/sim/wind.py


@dataclass(frozen=True)
class WindSpec:
    mean_m_s: Vec3 = (0.0, 0.0, 0.0)  # jet: the wind at the target's rest position
    gust_m_s: float = 0.0  # 1 sigma per horizontal axis (vertical: 30 %); jet: at the target
    gust_time_constant_s: float = 2.0
    model: str = "uniform"  # uniform | jet (a fan's round jet along mean_m_s)
    jet_source_m: Vec3 = (0.0, 0.0, 0.0)  # jet: the fan's outlet centre
    jet_diameter_m: float = 0.5  # jet: the fan's outlet diameter


@dataclass(frozen=True)
class SimSpec:
    physics_rate_hz: int = 600
    control_rate_hz: int = 100
    gyro_noise_rad_s: float = 0.003


@dataclass(frozen=True)
class EstimateSpec:
    """What the loop is handed instead of the truth (``groundstation/sim/estimate.py`` gives
    the model and the sources of each default). Sigmas are 1-sigma per axis."""

    enabled: bool = True  # false: ideal sensors (the loop sees the truth)
    pos_noise_m: float = 0.05  # Gauss-Markov position error
    pos_time_constant_s: float = 2.0
    vel_noise_m_s: float = 0.05  # Gauss-Markov velocity error
    vel_time_constant_s: float = 1.0
    att_noise_deg: float = 0.2  # Gauss-Markov attitude error (small rotation, body axes)
    att_time_constant_s: float = 2.0
    lag_s: float = 0.02  # the position and velocity estimates are the vehicle this long ago
    att_lag_s: float = 0.01  # the attitude estimate is the vehicle this long ago
    gyro_bias_rad_s: float = 0.003  # turn-on bias left after calibration
    gyro_bias_walk_rad_s_sqrt_s: float = 0.0001  # bias random walk
    camera_time_offset_s: float = 0.005  # camera-IMU stamp offset, drawn once a sortie
    camera_stamp_jitter_s: float = 0.001  # per frame, on top of the offset
    thrust_scale_sigma: float = 0.02  # true / modelled thrust, drawn once a sortie
    command_delay_s: float = 0.005  # command to actuators (MAVLink + PX4 scheduling)


@dataclass(frozen=True)
class Scenario:
    name: str
    duration_s: float
    interceptor: InterceptorSpec
    target: TargetSpec
    description: str = ""
    camera: CameraSpec = field(default_factory=CameraSpec)
    wind: WindSpec = field(default_factory=WindSpec)
    sim: SimSpec = field(default_factory=SimSpec)
    estimate: EstimateSpec = field(default_factory=EstimateSpec)
    gains: dict[str, float] = field(default_factory=dict)
    source: str = "<memory>"
    text: str = ""  # the file as read, for recording alongside a sortie

    def gains_obj(self) -> Gains:
        return Gains.from_mapping(self.gains, source=f"{self.source}: [gains]")


_SECTIONS = {
    "interceptor": InterceptorSpec,
    "target": TargetSpec,
    "camera": CameraSpec,
    "wind": WindSpec,
    "sim": SimSpec,
    "estimate": EstimateSpec,
}


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class _InvalidValueError(Exception):
    """A value of the wrong type (the message says what was expected)."""


_PLACEHOLDER: dict[str, Any] = {
    "float": 1.0,
    "int": 1,
    "str": "",
    "bool": True,
    "Vec3": (0.0, 0.0, 1.0),
}


def _convert(value: Any, annotation: str) -> Any:
    if annotation == "bool":
        if not isinstance(value, bool):
            raise _InvalidValueError(f"expected true or false, got {value!r}")
        return value
    if annotation == "float":
        if not _is_number(value) or not math.isfinite(value):
            raise _InvalidValueError(f"expected a number, got {value!r}")
        return float(value)
    if annotation == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise _InvalidValueError(f"expected an integer, got {value!r}")
        return value
    if annotation == "str":
        if not isinstance(value, str):
            raise _InvalidValueError(f"expected a string, got {value!r}")
        return value
    if annotation == "Vec3":
        if (
            not isinstance(value, list)
            or len(value) != 3
            or not all(_is_number(c) and math.isfinite(c) for c in value)
        ):
            raise _InvalidValueError(f"expected a list of 3 numbers, got {value!r}")
        return tuple(float(c) for c in value)
    raise AssertionError(annotation)  # pragma: no cover


_HEADER_RE = re.compile(r"^\s*\[\[?\s*([^\[\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY_RE = re.compile(
    r"""^\s*((?:[A-Za-z0-9_-]+|"[^"\n]*"|'[^'\n]*')"""
    r"""(?:\s*\.\s*(?:[A-Za-z0-9_-]+|"[^"\n]*"|'[^'\n]*'))*)\s*="""
)


def _dotted(key: str) -> str:
    return ".".join(part.strip().strip("\"'") for part in key.split("."))


def _key_positions(text: str) -> list[tuple[int, str]]:
    """(line, dotted name) of each table header and key in TOML text, in order; a light scan
    that only locates (tomllib checks the syntax)."""
    out: list[tuple[int, str]] = []
    table = ""
    in_string: str | None = None  # inside a multi-line string: its closing quotes
    for n, line in enumerate(text.splitlines(), 1):
        if in_string is not None:
            if in_string in line:
                in_string = None
            continue
        if m := _HEADER_RE.match(line):
            table = _dotted(m.group(1))
            out.append((n, table))
            continue
        if m := _KEY_RE.match(line):
            key = _dotted(m.group(1))
            out.append((n, f"{table}.{key}" if table else key))
            rest = line[m.end() :]
            for quotes in ('"""', "'''"):
                if rest.count(quotes) == 1:
                    in_string = quotes
    return out


def _key_lines(text: str) -> dict[str, int]:
    """Line (1-based) of each table header and key, by dotted name (the first if repeated)."""
    out: dict[str, int] = {}
    for n, key in _key_positions(text):
        out.setdefault(key, n)
    return out


class _Problems:
    """Collects every problem of one scenario, each located by its key's line."""

    def __init__(self, source: str, text: str = "") -> None:
        self.source = source
        self.lines = _key_lines(text) if text else {}
        self.found: list[ScenarioProblem] = []
        self.bad_keys: set[str] = set()

    def add(self, key: str | None, message: str) -> None:
        line = None
        if key is not None:
            self.bad_keys.add(key)
            line = self.lines.get(key, self.lines.get(key.partition(".")[0]))
        self.found.append(ScenarioProblem(key, message, line))

    def check(self, cond: bool, key: str, message: str) -> None:
        if key not in self.bad_keys and not cond:
            self.add(key, f"key '{key}': {message}")

    def raise_if_any(self) -> None:
        if self.found:
            raise ScenarioError(source=self.source, problems=self.found)


def _parse_table(table: Any, cls: type, section: str, problems: _Problems) -> Any:
    """The section as its dataclass; a bad value is recorded and replaced by a placeholder
    (its own checks are skipped) so that every other key is still checked."""
    if not isinstance(table, dict):
        problems.add(section, f"[{section}] must be a table")
        return None
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key in table:
        if key not in fields:
            problems.add(
                f"{section}.{key}",
                f"unknown key '{section}.{key}' (allowed: {', '.join(fields)})",
            )
    kwargs = {}
    for name, f in fields.items():
        key = f"{section}.{name}"
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        if name in table:
            try:
                kwargs[name] = _convert(table[name], str(f.type))
            except _InvalidValueError as exc:
                problems.add(key, f"key '{key}': {exc}")
                if required:
                    kwargs[name] = _PLACEHOLDER[str(f.type)]
        elif required:
            problems.add(key, f"missing required key '{key}'")
            kwargs[name] = _PLACEHOLDER[str(f.type)]
    return cls(**kwargs)


def _validate(s: Scenario, problems: _Problems) -> None:
    t, c, i, sim = s.target, s.camera, s.interceptor, s.sim
    check = problems.check
    check(s.duration_s > 0, "duration_s", "must be positive")
    check(t.motion in MOTIONS, "target.motion", f"must be one of {', '.join(MOTIONS)}")
    check(t.diameter_m > 0, "target.diameter_m", "must be positive")
    if t.motion == "sinusoid":
        check(t.period_s > 0, "target.period_s", "sinusoid needs a positive period")
    if t.motion == "circle":
        check(t.radius_m > 0, "target.radius_m", "circle needs a positive radius")
        check(t.period_s != 0, "target.period_s", "circle needs a non-zero period")
    if t.motion == "escape":
        check(t.max_speed_m_s > 0, "target.max_speed_m_s", "must be positive")
    if t.motion == "tethered":
        check(t.tether_length_m > 0, "target.tether_length_m", "must be positive")
        check(t.mass_kg >= 0, "target.mass_kg", "must be positive (0: from the physics)")
        check(t.net_lift_n >= 0, "target.net_lift_n", "must be positive (0: from the physics)")
        check(t.envelope_mass_kg > 0, "target.envelope_mass_kg", "must be positive")
        check(t.drag_coefficient > 0, "target.drag_coefficient", "must be positive")
        if t.net_lift_n == 0 and t.diameter_m > 0 and t.envelope_mass_kg > 0:
            gross = helium_gross_lift_n(t.diameter_m)
            check(
                gross > t.envelope_mass_kg * GRAVITY_M_S2,
                "target.envelope_mass_kg",
                f"{t.envelope_mass_kg} kg is more than a {t.diameter_m} m helium balloon lifts "
                f"({gross / GRAVITY_M_S2 * 1000:.2f} g gross): it would not fly",
            )
    check(t.start_s >= 0, "target.start_s", "must not be negative")
    check(i.position_m[2] > 0, "interceptor.position_m", "must start above ground (z > 0)")
    check(i.size_m > 0, "interceptor.size_m", "must be positive")
    check(i.mass_kg > 0, "interceptor.mass_kg", "must be positive")
    check(i.thrust_to_weight > 1, "interceptor.thrust_to_weight", "must exceed 1")
    check(i.drag_n_s_m >= 0, "interceptor.drag_n_s_m", "must not be negative")
    check(i.rate_time_constant_s > 0, "interceptor.rate_time_constant_s", "must be > 0")
    check(i.thrust_time_constant_s > 0, "interceptor.thrust_time_constant_s", "must be > 0")
    check(i.max_rate_deg_s > 0, "interceptor.max_rate_deg_s", "must be positive")
    check(c.width_px >= 16, "camera.width_px", "frame too small (at least 16 px)")
    check(c.height_px >= 16, "camera.height_px", "frame too small (at least 16 px)")
    check(1 <= c.hfov_deg <= 170, "camera.hfov_deg", "must be in [1, 170]")
    check(c.rate_hz > 0, "camera.rate_hz", "must be positive")
    check(c.delay_s >= 0, "camera.delay_s", "must be >= 0")
    check(c.delay_jitter_s >= 0, "camera.delay_jitter_s", "must be >= 0")
    check(c.noise_px >= 0, "camera.noise_px", "must not be negative")
    check(0 <= c.dropout_probability < 1, "camera.dropout_probability", "must be in [0, 1)")
    check(0 <= c.min_blob_px <= 100, "camera.min_blob_px", "must be in [0, 100] px")
    check(0 <= c.false_probability <= 1, "camera.false_probability", "must be in [0, 1]")
    check(0 < c.false_blob_px <= 100, "camera.false_blob_px", "must be in (0, 100] px")
    check(0 <= c.burst_probability < 1, "camera.burst_probability", "must be in [0, 1)")
    check(c.burst_mean_frames >= 1, "camera.burst_mean_frames", "must be at least 1 frame")
    check(0 <= c.burst_drop_probability <= 1, "camera.burst_drop_probability", "must be in [0, 1]")
    check(s.wind.gust_m_s >= 0, "wind.gust_m_s", "must not be negative")
    check(s.wind.gust_time_constant_s > 0, "wind.gust_time_constant_s", "must be > 0")
    w = s.wind
    check(w.model in WIND_MODELS, "wind.model", f"must be one of {', '.join(WIND_MODELS)}")
    if w.model == "jet":
        check(w.jet_diameter_m > 0, "wind.jet_diameter_m", "must be positive")
        problem = jet_reference_problem(w, t.position_m) if w.jet_diameter_m > 0 else None
        check(problem is None, "wind.jet_source_m", problem or "")
    check(sim.physics_rate_hz >= 500, "sim.physics_rate_hz", "must be at least 500")
    for key, rate in (("sim.control_rate_hz", sim.control_rate_hz), ("camera.rate_hz", c.rate_hz)):
        ratio = sim.physics_rate_hz / rate if rate > 0 else math.nan
        check(
            abs(ratio - round(ratio)) < 1e-9 and round(ratio) >= 1 if rate > 0 else False,
            key,
            f"{rate} Hz must divide the physics rate {sim.physics_rate_hz} Hz",
        )
    check(sim.gyro_noise_rad_s >= 0, "sim.gyro_noise_rad_s", "must not be negative")
    e = s.estimate
    for name in (
        "pos_noise_m",
        "vel_noise_m_s",
        "att_noise_deg",
        "lag_s",
        "att_lag_s",
        "gyro_bias_rad_s",
        "gyro_bias_walk_rad_s_sqrt_s",
        "camera_time_offset_s",
        "camera_stamp_jitter_s",
        "thrust_scale_sigma",
        "command_delay_s",
    ):
        check(getattr(e, name) >= 0, f"estimate.{name}", "must not be negative")
    for name in ("pos_time_constant_s", "vel_time_constant_s", "att_time_constant_s"):
        check(getattr(e, name) > 0, f"estimate.{name}", "must be > 0")
    check(e.lag_s <= 0.5, "estimate.lag_s", "must be at most 0.5 s")
    check(e.att_lag_s <= 0.5, "estimate.att_lag_s", "must be at most 0.5 s")
    check(e.command_delay_s <= 0.5, "estimate.command_delay_s", "must be at most 0.5 s")
    check(e.att_noise_deg <= 10, "estimate.att_noise_deg", "must be at most 10 degrees")
    check(e.thrust_scale_sigma <= 0.2, "estimate.thrust_scale_sigma", "must be at most 0.2")
    check(
        e.camera_time_offset_s <= 0.05,
        "estimate.camera_time_offset_s",
        "must be at most 0.05 s (a larger offset is a wrong camera delay, camera.delay_s)",
    )
    each_ok = True
    for k, v in s.gains.items():
        try:
            Gains().replace(**{k: v})
        except GainError as exc:
            each_ok = False
            problems.add(f"gains.{k}", f"key 'gains.{k}': {exc}")
    if each_ok:
        try:
            s.gains_obj()
        except GainError as exc:
            problems.add("gains", str(exc))


AIR_DENSITY_KG_M3 = 1.2  # sea level, 20 C
HELIUM_DENSITY_KG_M3 = 0.166  # at 1 atm, 20 C (a party balloon's slight overpressure ignored)


def helium_gross_lift_n(diameter_m: float) -> float:
    """Buoyancy minus the helium's weight of a sphere (N): (rho_air - rho_He) V g."""
    volume = math.pi / 6.0 * diameter_m**3
    return (AIR_DENSITY_KG_M3 - HELIUM_DENSITY_KG_M3) * volume * GRAVITY_M_S2


def balloon_lift_and_mass(target: TargetSpec) -> tuple[float, float]:
    """(net lift N, effective mass kg) of a tethered helium balloon: the file's values, or
    where they are 0 the physics: net lift = (rho_air - rho_He) V g - m_envelope g; mass =
    m_envelope + rho_He V + rho_air V / 2, the last the added mass of a sphere accelerating in
    air (Lamb, *Hydrodynamics* §92; Newman, *Marine Hydrodynamics* §4.13). For the paper's
    0.16 m balloon with a 1.5 g envelope: 0.0071 N and 3.1 g."""
    volume = math.pi / 6.0 * target.diameter_m**3
    lift = target.net_lift_n or (
        helium_gross_lift_n(target.diameter_m) - target.envelope_mass_kg * GRAVITY_M_S2
    )
    mass = target.mass_kg or (
        target.envelope_mass_kg + HELIUM_DENSITY_KG_M3 * volume + 0.5 * AIR_DENSITY_KG_M3 * volume
    )
    return lift, mass


def jet_reference_problem(wind: WindSpec, reference_m: Vec3) -> str | None:
    """Why a fan jet cannot set its speed at ``reference_m`` (the target's rest position),
    or None: the point must be downstream of the fan."""
    m = wind.mean_m_s
    speed = math.sqrt(sum(c * c for c in m))
    if speed == 0.0:
        return None
    x = sum((reference_m[i] - wind.jet_source_m[i]) * m[i] for i in range(3)) / speed
    if x <= 0.0:
        return (
            "the fan must be upwind of the target: the target's rest position is "
            f"{-x:.2f} m behind the fan along wind.mean_m_s"
        )
    return None


def _syntax_error(exc: Exception, source: str, text: str) -> ScenarioError:
    """tomllib's error as a located problem (it stops at the first syntax error). Where it
    gives no position (a key defined twice, the end of the document), the scan finds it."""
    message = str(exc)
    line = column = None
    m = re.search(r"\s*\(at line (\d+), column (\d+)\)", message)
    if m is not None:
        line, column = int(m.group(1)), int(m.group(2))
    else:
        m = re.search(r"\s*\(at end of document\)", message)
        seen: dict[str, int] = {}
        for n, key in _key_positions(text):
            if key in seen:  # a key (or table) defined twice: the second one is the error
                line = n
                break
            seen[key] = n
        if line is None:
            lines = text.split("\n")
            line, column = len(lines), len(lines[-1]) + 1
    reason = message[: m.start()] if m is not None else message
    problem = ScenarioProblem(None, f"not valid TOML: {reason}", line, column)
    return ScenarioError(source=source, problems=[problem])


def parse_scenario(text: str, source: str = "<memory>") -> Scenario:
    """Parse and validate scenario TOML text; a :class:`ScenarioError` lists every problem."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _syntax_error(exc, source, text) from None
    problems = _Problems(source, text)
    top_fields = {"name": "str", "duration_s": "float", "description": "str"}
    for key in data:
        if key not in top_fields and key not in _SECTIONS and key != "gains":
            allowed = ", ".join([*top_fields, *_SECTIONS, "gains"])
            problems.add(key, f"unknown key '{key}' (allowed: {allowed})")
    kwargs: dict[str, Any] = {"source": source, "text": text}
    for key, ann in top_fields.items():
        if key in data:
            try:
                kwargs[key] = _convert(data[key], ann)
            except _InvalidValueError as exc:
                problems.add(key, f"key '{key}': {exc}")
                kwargs[key] = _PLACEHOLDER[ann]
        elif key != "description":
            problems.add(key, f"missing required key '{key}'")
            kwargs[key] = _PLACEHOLDER[ann]
    complete = True
    for section, cls in _SECTIONS.items():
        if section in data:
            spec = _parse_table(data[section], cls, section, problems)
            if spec is not None:
                kwargs[section] = spec
            elif section in ("interceptor", "target"):
                complete = False
        elif section in ("interceptor", "target"):
            problems.add(section, f"missing required table '[{section}]'")
            complete = False
    if "gains" in data:
        if not isinstance(data["gains"], dict):
            problems.add("gains", "[gains] must be a table")
        else:
            gains = {}
            for k, v in data["gains"].items():
                if _is_number(v):
                    gains[k] = float(v)
                else:
                    problems.add(f"gains.{k}", f"key 'gains.{k}': expected a number, got {v!r}")
            kwargs["gains"] = gains
    if complete:
        scenario = Scenario(**kwargs)
        _validate(scenario, problems)
    problems.raise_if_any()
    return scenario


def load_scenario(path: str | Path) -> Scenario:
    """Load a scenario file; a bare name is looked up among the shipped scenarios."""
    p = Path(path)
    if not p.exists() and not p.suffix and (SCENARIO_DIR / f"{p.name}.toml").exists():
        p = SCENARIO_DIR / f"{p.name}.toml"
    if p.is_dir():
        raise ScenarioError(f"{path}: is a folder, not a scenario file", source=str(path))
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: cannot read scenario file: {exc}", source=str(path)) from None
    return parse_scenario(text, source=str(path))


def shipped_scenarios() -> list[Path]:
    return sorted(SCENARIO_DIR.glob("*.toml"))


def with_changes(scenario: Scenario, **sections: Any) -> Scenario:
    """A copy with whole sections or top-level values replaced, validated again. The copy is
    no longer its file, so its TOML (:func:`scenario_toml`) is generated from its values."""
    s = dataclasses.replace(scenario, text="", **sections)
    problems = _Problems(s.source)
    _validate(s, problems)
    problems.raise_if_any()
    return s


_SET_EXAMPLE = "e.g. camera.noise_px=0 or gains.k_v=2"


def parse_overrides(items: Sequence[str] | None) -> dict[str, Any]:
    """``["camera.noise_px=0", "gains.k_v=100"]`` -> ``{"camera.noise_px": 0, ...}``; each
    value is read as TOML (numbers, strings in quotes, arrays). Only the syntax is checked
    here; :func:`with_overrides` checks names, types and ranges. Every bad item is listed."""
    out: dict[str, Any] = {}
    problems = _Problems("--set")
    for item in items or ():
        key, sep, text = item.partition("=")
        key = key.strip()
        if not key or not sep:
            problems.add(None, f"{item!r}: expected SECTION.KEY=VALUE, {_SET_EXAMPLE}")
            continue
        if not text.strip():
            problems.add(key, f"{item!r}: no value after '=' ({_SET_EXAMPLE})")
            continue
        try:
            out[key] = tomllib.loads(f"v = {text.strip()}")["v"]
        except (tomllib.TOMLDecodeError, KeyError):
            problems.add(
                key,
                f"{key}: {text.strip()!r} is not a value (write a number, true/false, "
                '"text" in double quotes or [1, 2, 3])',
            )
    problems.raise_if_any()
    return out


def with_overrides(scenario: Scenario, overrides: Mapping[str, Any]) -> Scenario:
    """A copy with single values replaced: ``section.key`` (``camera``, ``wind``, ...,
    ``gains``) or a top-level key such as ``duration_s``. Every value is checked as if it had
    been in the file; the error lists every bad key and nothing is changed."""
    if not overrides:
        return scenario
    problems = _Problems("--set")
    tables: dict[str, dict[str, Any]] = {}
    top: dict[str, Any] = {}
    for key, value in overrides.items():
        section, dot, name = key.partition(".")
        if not dot:
            if key not in ("name", "duration_s", "description"):
                problems.add(
                    key,
                    f"unknown key '{key}' (a top-level key is name, duration_s or "
                    "description; others are SECTION.KEY)",
                )
                continue
            try:
                top[key] = _convert(value, "float" if key == "duration_s" else "str")
            except _InvalidValueError as exc:
                problems.add(key, f"key '{key}': {exc}")
            continue
        if section != "gains" and section not in _SECTIONS:
            allowed = ", ".join([*_SECTIONS, "gains"])
            problems.add(key, f"unknown section '{section}' (allowed: {allowed})")
            continue
        tables.setdefault(section, {})[name] = value
    changes: dict[str, Any] = dict(top)
    for section, values in tables.items():
        if section == "gains":
            gains = dict(scenario.gains)
            for k, v in values.items():
                try:
                    gains[k] = _convert(v, "float")
                except _InvalidValueError as exc:
                    problems.add(f"gains.{k}", f"key 'gains.{k}': {exc}")
            changes["gains"] = gains
        else:
            merged = {**_as_toml_table(getattr(scenario, section)), **values}
            spec = _parse_table(merged, _SECTIONS[section], section, problems)
            if spec is not None:
                changes[section] = spec
    problems.raise_if_any()
    changed = dataclasses.replace(
        scenario, text="", source=f"--set on {scenario.source}", **changes
    )
    _validate(changed, problems)
    problems.source = changed.source
    problems.raise_if_any()
    return dataclasses.replace(changed, source=scenario.source)


def _as_toml_table(spec: Any) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(spec).items()}


def scenario_toml(scenario: Scenario) -> str:
    """The scenario as TOML: its file as read if it is unchanged, else generated from its
    values (every key written, so it reads back to an equal scenario). A file without an
    ``[estimate]`` table gets the one that applies appended, so a recording names the
    estimate settings that flew."""
    if scenario.text:
        if "estimate" in tomllib.loads(scenario.text):
            return scenario.text
        table = tomli_w.dumps({"estimate": _as_toml_table(scenario.estimate)})
        sep = "" if scenario.text.endswith("\n") else "\n"
        return (
            f"{scenario.text}{sep}\n# not in the file: the state-estimate model's defaults, "
            f"as flown\n{table}"
        )
    data: dict[str, Any] = {
        "name": scenario.name,
        "description": scenario.description,
        "duration_s": scenario.duration_s,
    }
    for section in _SECTIONS:
        data[section] = _as_toml_table(getattr(scenario, section))
    if scenario.gains:
        data["gains"] = dict(scenario.gains)
    return tomli_w.dumps(data)
