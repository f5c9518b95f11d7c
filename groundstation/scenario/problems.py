"""What is wrong with a scenario, located: :class:`ScenarioProblem` (a key, a message, a line
and column), :class:`ScenarioError` carrying every problem found, and the light scan of the
TOML text that finds each key's line."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any


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


class Problems:
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


def syntax_error(exc: Exception, source: str, text: str) -> ScenarioError:
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
