"""Single values changed from the command line (``--set camera.noise_px=0``), checked as if
they had been in the file, and a scenario written back as TOML."""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Mapping, Sequence
from typing import Any

import tomli_w

from .loading import InvalidValueError, convert, parse_table
from .problems import Problems
from .specs import SECTIONS, Scenario
from .validate import validate

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


_SET_EXAMPLE = "e.g. camera.noise_px=0 or gains.k_v=2"


def parse_overrides(items: Sequence[str] | None) -> dict[str, Any]:
    """``["camera.noise_px=0", "gains.k_v=100"]`` -> ``{"camera.noise_px": 0, ...}``; each
    value is read as TOML (numbers, strings in quotes, arrays). Only the syntax is checked
    here; :func:`with_overrides` checks names, types and ranges. Every bad item is listed."""
    out: dict[str, Any] = {}
    problems = Problems("--set")
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
    problems = Problems("--set")
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
                top[key] = convert(value, "float" if key == "duration_s" else "str")
            except InvalidValueError as exc:
                problems.add(key, f"key '{key}': {exc}")
            continue
        if section != "gains" and section not in SECTIONS:
            allowed = ", ".join([*SECTIONS, "gains"])
            problems.add(key, f"unknown section '{section}' (allowed: {allowed})")
            continue
        tables.setdefault(section, {})[name] = value
    changes: dict[str, Any] = dict(top)
    for section, values in tables.items():
        if section == "gains":
            gains = dict(scenario.gains)
            for k, v in values.items():
                try:
                    gains[k] = convert(v, "float")
                except InvalidValueError as exc:
                    problems.add(f"gains.{k}", f"key 'gains.{k}': {exc}")
            changes["gains"] = gains
        else:
            merged = {**as_toml_table(getattr(scenario, section)), **values}
            spec = parse_table(merged, SECTIONS[section], section, problems)
            if spec is not None:
                changes[section] = spec
    problems.raise_if_any()
    changed = dataclasses.replace(
        scenario, text="", source=f"--set on {scenario.source}", **changes
    )
    validate(changed, problems)
    problems.source = changed.source
    problems.raise_if_any()
    return dataclasses.replace(changed, source=scenario.source)


def as_toml_table(spec: Any) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(spec).items()}


def scenario_toml(scenario: Scenario) -> str:
    """The scenario as TOML: its file as read if it is unchanged, else generated from its
    values (every key written, so it reads back to an equal scenario). A file without an
    ``[estimate]`` table gets the one that applies appended, so a recording names the
    estimate settings that flew."""
    if scenario.text:
        if "estimate" in tomllib.loads(scenario.text):
            return scenario.text
        table = tomli_w.dumps({"estimate": as_toml_table(scenario.estimate)})
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
    for section in SECTIONS:
        data[section] = as_toml_table(getattr(scenario, section))
    if scenario.gains:
        data["gains"] = dict(scenario.gains)
    return tomli_w.dumps(data)
