"""Scenario TOML to a :class:`Scenario`: strict typed parsing of each section, then the value
checks; every problem is collected before :class:`ScenarioError` is raised."""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path
from typing import Any

from .problems import Problems, ScenarioError, syntax_error
from .specs import SCENARIO_DIR, SECTIONS, Scenario
from .validate import validate

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class InvalidValueError(Exception):
    """A value of the wrong type (the message says what was expected)."""


PLACEHOLDER: dict[str, Any] = {
    "float": 1.0,
    "int": 1,
    "str": "",
    "bool": True,
    "Vec3": (0.0, 0.0, 1.0),
}


def convert(value: Any, annotation: str) -> Any:
    if annotation == "bool":
        if not isinstance(value, bool):
            raise InvalidValueError(f"expected true or false, got {value!r}")
        return value
    if annotation == "float":
        if not is_number(value) or not math.isfinite(value):
            raise InvalidValueError(f"expected a number, got {value!r}")
        return float(value)
    if annotation == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise InvalidValueError(f"expected an integer, got {value!r}")
        return value
    if annotation == "str":
        if not isinstance(value, str):
            raise InvalidValueError(f"expected a string, got {value!r}")
        return value
    if annotation == "Vec3":
        if (
            not isinstance(value, list)
            or len(value) != 3
            or not all(is_number(c) and math.isfinite(c) for c in value)
        ):
            raise InvalidValueError(f"expected a list of 3 numbers, got {value!r}")
        return tuple(float(c) for c in value)
    raise AssertionError(annotation)  # pragma: no cover


def parse_table(table: Any, cls: type, section: str, problems: Problems) -> Any:
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
                kwargs[name] = convert(table[name], str(f.type))
            except InvalidValueError as exc:
                problems.add(key, f"key '{key}': {exc}")
                if required:
                    kwargs[name] = PLACEHOLDER[str(f.type)]
        elif required:
            problems.add(key, f"missing required key '{key}'")
            kwargs[name] = PLACEHOLDER[str(f.type)]
    return cls(**kwargs)


def parse_scenario(text: str, source: str = "<memory>") -> Scenario:
    """Parse and validate scenario TOML text; a :class:`ScenarioError` lists every problem."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise syntax_error(exc, source, text) from None
    problems = Problems(source, text)
    top_fields = {"name": "str", "duration_s": "float", "description": "str"}
    for key in data:
        if key not in top_fields and key not in SECTIONS and key != "gains":
            allowed = ", ".join([*top_fields, *SECTIONS, "gains"])
            problems.add(key, f"unknown key '{key}' (allowed: {allowed})")
    kwargs: dict[str, Any] = {"source": source, "text": text}
    for key, ann in top_fields.items():
        if key in data:
            try:
                kwargs[key] = convert(data[key], ann)
            except InvalidValueError as exc:
                problems.add(key, f"key '{key}': {exc}")
                kwargs[key] = PLACEHOLDER[ann]
        elif key != "description":
            problems.add(key, f"missing required key '{key}'")
            kwargs[key] = PLACEHOLDER[ann]
    complete = True
    for section, cls in SECTIONS.items():
        if section in data:
            spec = parse_table(data[section], cls, section, problems)
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
                if is_number(v):
                    gains[k] = float(v)
                else:
                    problems.add(f"gains.{k}", f"key 'gains.{k}': expected a number, got {v!r}")
            kwargs["gains"] = gains
    if complete:
        scenario = Scenario(**kwargs)
        validate(scenario, problems)
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
    problems = Problems(s.source)
    validate(s, problems)
    problems.raise_if_any()
    return s
