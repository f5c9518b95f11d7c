"""Scenario files (TOML): strict loading into typed dataclasses.

Every section is a dataclass below; its fields are the allowed keys, fields without a default
are required, and the annotation gives the type. An unknown key, a missing required key, a
wrong type or an impossible value raises :class:`ScenarioError` naming the file and the key.
Angles are degrees in the file and stay so named (``yaw_deg``); they are converted where used.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from onboard.gains import GainError, Gains

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

Vec3 = tuple[float, float, float]
MOTIONS = ("static", "cv", "ca", "sinusoid", "circle", "escape", "takeoff", "tethered")
SCENARIO_DIR = Path(__file__).parent / "scenarios"


class ScenarioError(ValueError):
    """A scenario file is malformed; the message names the file and the key."""


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
    net_lift_n: float = 0.03  # tethered: buoyancy minus weight
    mass_kg: float = 0.015  # tethered: balloon plus added air mass
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


@dataclass(frozen=True)
class WindSpec:
    mean_m_s: Vec3 = (0.0, 0.0, 0.0)
    gust_m_s: float = 0.0  # 1 sigma per horizontal axis (vertical: 30 %)
    gust_time_constant_s: float = 2.0


@dataclass(frozen=True)
class SimSpec:
    physics_rate_hz: int = 600
    control_rate_hz: int = 100
    gyro_noise_rad_s: float = 0.003


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
}


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _convert(value: Any, annotation: str, where: str) -> Any:
    if annotation == "float":
        if not _is_number(value) or not math.isfinite(value):
            raise ScenarioError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if annotation == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(f"{where}: expected an integer, got {value!r}")
        return value
    if annotation == "str":
        if not isinstance(value, str):
            raise ScenarioError(f"{where}: expected a string, got {value!r}")
        return value
    if annotation == "Vec3":
        if (
            not isinstance(value, list)
            or len(value) != 3
            or not all(_is_number(c) and math.isfinite(c) for c in value)
        ):
            raise ScenarioError(f"{where}: expected a list of 3 numbers, got {value!r}")
        return tuple(float(c) for c in value)
    raise AssertionError(annotation)  # pragma: no cover


def _parse_table(table: Any, cls: type, section: str, src: str) -> Any:
    if not isinstance(table, dict):
        raise ScenarioError(f"{src}: [{section}] must be a table")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key in table:
        if key not in fields:
            raise ScenarioError(
                f"{src}: unknown key '{section}.{key}' (allowed: {', '.join(fields)})"
            )
    kwargs = {}
    for name, f in fields.items():
        if name in table:
            kwargs[name] = _convert(table[name], str(f.type), f"{src}: key '{section}.{name}'")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ScenarioError(f"{src}: missing required key '{section}.{name}'")
    return cls(**kwargs)


def _check(cond: bool, src: str, key: str, msg: str) -> None:
    if not cond:
        raise ScenarioError(f"{src}: key '{key}': {msg}")


def _validate(s: Scenario) -> None:
    src, t, c, i, sim = s.source, s.target, s.camera, s.interceptor, s.sim
    _check(s.duration_s > 0, src, "duration_s", "must be positive")
    _check(t.motion in MOTIONS, src, "target.motion", f"must be one of {', '.join(MOTIONS)}")
    _check(t.diameter_m > 0, src, "target.diameter_m", "must be positive")
    if t.motion == "sinusoid":
        _check(t.period_s > 0, src, "target.period_s", "sinusoid needs a positive period")
    if t.motion == "circle":
        _check(t.radius_m > 0, src, "target.radius_m", "circle needs a positive radius")
        _check(t.period_s != 0, src, "target.period_s", "circle needs a non-zero period")
    if t.motion == "escape":
        _check(t.max_speed_m_s > 0, src, "target.max_speed_m_s", "must be positive")
    if t.motion == "tethered":
        _check(t.tether_length_m > 0, src, "target.tether_length_m", "must be positive")
        _check(t.mass_kg > 0, src, "target.mass_kg", "must be positive")
        _check(t.net_lift_n > 0, src, "target.net_lift_n", "a tethered balloon must lift")
    _check(t.start_s >= 0, src, "target.start_s", "must not be negative")
    _check(i.position_m[2] > 0, src, "interceptor.position_m", "must start above ground (z > 0)")
    _check(i.size_m > 0, src, "interceptor.size_m", "must be positive")
    _check(i.mass_kg > 0, src, "interceptor.mass_kg", "must be positive")
    _check(i.thrust_to_weight > 1, src, "interceptor.thrust_to_weight", "must exceed 1")
    _check(i.drag_n_s_m >= 0, src, "interceptor.drag_n_s_m", "must not be negative")
    _check(i.rate_time_constant_s > 0, src, "interceptor.rate_time_constant_s", "must be > 0")
    _check(i.thrust_time_constant_s > 0, src, "interceptor.thrust_time_constant_s", "must be > 0")
    _check(i.max_rate_deg_s > 0, src, "interceptor.max_rate_deg_s", "must be positive")
    _check(c.width_px >= 16 and c.height_px >= 16, src, "camera.width_px", "frame too small")
    _check(1 <= c.hfov_deg <= 170, src, "camera.hfov_deg", "must be in [1, 170]")
    _check(c.rate_hz > 0, src, "camera.rate_hz", "must be positive")
    _check(c.delay_s >= 0 and c.delay_jitter_s >= 0, src, "camera.delay_s", "must be >= 0")
    _check(c.noise_px >= 0, src, "camera.noise_px", "must not be negative")
    _check(0 <= c.dropout_probability < 1, src, "camera.dropout_probability", "must be in [0, 1)")
    _check(s.wind.gust_m_s >= 0, src, "wind.gust_m_s", "must not be negative")
    _check(s.wind.gust_time_constant_s > 0, src, "wind.gust_time_constant_s", "must be > 0")
    _check(sim.physics_rate_hz >= 500, src, "sim.physics_rate_hz", "must be at least 500")
    for key, rate in (("sim.control_rate_hz", sim.control_rate_hz), ("camera.rate_hz", c.rate_hz)):
        ratio = sim.physics_rate_hz / rate if rate > 0 else math.nan
        _check(
            abs(ratio - round(ratio)) < 1e-9 and round(ratio) >= 1,
            src,
            key,
            f"{rate} Hz must divide the physics rate {sim.physics_rate_hz} Hz",
        )
    _check(sim.gyro_noise_rad_s >= 0, src, "sim.gyro_noise_rad_s", "must not be negative")
    try:
        s.gains_obj()
    except GainError as exc:
        raise ScenarioError(str(exc)) from None


def parse_scenario(text: str, source: str = "<memory>") -> Scenario:
    """Parse and validate scenario TOML text."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    top_fields = {"name": "str", "duration_s": "float", "description": "str"}
    for key in data:
        if key not in top_fields and key not in _SECTIONS and key != "gains":
            allowed = ", ".join([*top_fields, *_SECTIONS, "gains"])
            raise ScenarioError(f"{source}: unknown key '{key}' (allowed: {allowed})")
    kwargs: dict[str, Any] = {"source": source, "text": text}
    for key, ann in top_fields.items():
        if key in data:
            kwargs[key] = _convert(data[key], ann, f"{source}: key '{key}'")
        elif key != "description":
            raise ScenarioError(f"{source}: missing required key '{key}'")
    for section, cls in _SECTIONS.items():
        if section in data:
            kwargs[section] = _parse_table(data[section], cls, section, source)
        elif section in ("interceptor", "target"):
            raise ScenarioError(f"{source}: missing required table '[{section}]'")
    if "gains" in data:
        if not isinstance(data["gains"], dict):
            raise ScenarioError(f"{source}: [gains] must be a table")
        for k, v in data["gains"].items():
            if not _is_number(v):
                raise ScenarioError(f"{source}: key 'gains.{k}': expected a number, got {v!r}")
        kwargs["gains"] = {k: float(v) for k, v in data["gains"].items()}
    scenario = Scenario(**kwargs)
    _validate(scenario)
    return scenario


def load_scenario(path: str | Path) -> Scenario:
    """Load a scenario file; a bare name is looked up among the shipped scenarios."""
    p = Path(path)
    if not p.exists() and not p.suffix and (SCENARIO_DIR / f"{p.name}.toml").exists():
        p = SCENARIO_DIR / f"{p.name}.toml"
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: cannot read scenario file: {exc}") from None
    return parse_scenario(text, source=str(path))


def shipped_scenarios() -> list[Path]:
    return sorted(SCENARIO_DIR.glob("*.toml"))


def with_changes(scenario: Scenario, **sections: Any) -> Scenario:
    """A copy with whole sections or top-level values replaced, validated again. The copy is
    no longer its file, so its TOML (:func:`scenario_toml`) is generated from its values."""
    s = dataclasses.replace(scenario, text="", **sections)
    _validate(s)
    return s


def parse_overrides(items: Sequence[str] | None) -> dict[str, Any]:
    """``["camera.noise_px=0", "gains.k_v=100"]`` -> ``{"camera.noise_px": 0, ...}``; each
    value is read as TOML (numbers, strings in quotes, arrays). Only the syntax is checked
    here; :func:`with_overrides` checks names, types and ranges."""
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, text = item.partition("=")
        key = key.strip()
        value = None
        if sep and text.strip():
            with contextlib.suppress(tomllib.TOMLDecodeError):
                value = tomllib.loads(f"v = {text.strip()}")["v"]
        if not key or value is None:
            raise ScenarioError(
                f"--set {item!r}: expected SECTION.KEY=VALUE, e.g. camera.noise_px=0 or gains.k_v=2"
            )
        out[key] = value
    return out


def with_overrides(scenario: Scenario, overrides: Mapping[str, Any]) -> Scenario:
    """A copy with single values replaced: ``section.key`` (``camera``, ``wind``, ...,
    ``gains``) or a top-level key such as ``duration_s``. Every value is checked as if it had
    been in the file; an error names the key and changes nothing."""
    if not overrides:
        return scenario
    src = "--set"
    tables: dict[str, dict[str, Any]] = {}
    top: dict[str, Any] = {}
    for key, value in overrides.items():
        section, dot, name = key.partition(".")
        if not dot:
            if key not in ("name", "duration_s", "description"):
                raise ScenarioError(
                    f"{src}: unknown key '{key}' (a top-level key is name, duration_s or "
                    "description; others are SECTION.KEY)"
                )
            top[key] = _convert(value, "float" if key == "duration_s" else "str", f"{src} {key}")
            continue
        if section != "gains" and section not in _SECTIONS:
            allowed = ", ".join([*_SECTIONS, "gains"])
            raise ScenarioError(f"{src}: unknown section '{section}' (allowed: {allowed})")
        tables.setdefault(section, {})[name] = value
    changes: dict[str, Any] = dict(top)
    for section, values in tables.items():
        if section == "gains":
            for k, v in values.items():
                _convert(v, "float", f"{src} gains.{k}")
            changes["gains"] = {**scenario.gains, **{k: float(v) for k, v in values.items()}}
        else:
            merged = {**_as_toml_table(getattr(scenario, section)), **values}
            changes[section] = _parse_table(merged, _SECTIONS[section], section, src)
    changed = with_changes(
        dataclasses.replace(scenario, source=f"--set on {scenario.source}"), **changes
    )
    return dataclasses.replace(changed, source=scenario.source)


def _as_toml_table(spec: Any) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(spec).items()}


def scenario_toml(scenario: Scenario) -> str:
    """The scenario as TOML: its file as read if it is unchanged, else generated from its
    values (every key written, so it reads back to an equal scenario)."""
    if scenario.text:
        return scenario.text
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
