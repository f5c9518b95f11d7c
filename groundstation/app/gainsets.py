"""Named gain sets kept on disk (one TOML file of ``name = value`` lines per set, readable by
``onboard gains --check``), so they survive a restart."""

from __future__ import annotations

import os
import re
from pathlib import Path

import tomllib

from onboard.gains import GainError, Gains, load_gains_file

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,47}$")


def default_data_dir() -> Path:
    return Path(os.environ.get("PEREGRINE_HOME", Path.home() / ".peregrine"))


class GainSetError(ValueError):
    """A gain set refused; ``problems`` lists every one found."""

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        super().__init__(message)
        self.problems = problems or [message]


class GainSetStore:
    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)

    def _path(self, name: str) -> Path:
        if not _NAME.match(name) or name.endswith(".") or ".." in name:
            raise GainSetError(
                f"bad gain set name {name!r}: letters, digits, '_', '-', '.'; at most 48"
            )
        return self.directory / f"{name}.toml"

    def names(self) -> list[str]:
        if not self.directory.is_dir():
            return []
        return sorted(p.stem for p in self.directory.glob("*.toml") if _NAME.match(p.stem))

    def save(self, name: str, gains: Gains) -> None:
        path = self._path(name)
        self.directory.mkdir(parents=True, exist_ok=True)
        text = "".join(f"{k} = {v!r}\n" for k, v in gains.to_dict().items())
        tmp = path.with_suffix(".toml.tmp")
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)  # atomic: a crash never leaves half a file

    def text(self, name: str) -> str:
        """The file of a saved set (for download)."""
        path = self._path(name)
        if not path.is_file():
            raise GainSetError(f"no gain set named {name!r}")
        return path.read_text(encoding="utf-8")

    def save_text(self, name: str, text: str) -> Gains:
        """Save an uploaded file as set ``name``, checked first: a bad file changes nothing."""
        self._path(name)
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            why = f"not valid TOML: {exc}"
            raise GainSetError(f"gain set file {name!r} refused, nothing saved: {why}") from None
        problems = []
        for k, v in data.items():
            try:
                Gains().replace(**{k: v})
            except (GainError, TypeError) as exc:
                problems.append(str(exc))
        if problems:
            raise GainSetError(
                f"gain set file {name!r} refused, nothing saved: {len(problems)} problem"
                f"{'s' if len(problems) > 1 else ''}: " + "; ".join(problems),
                problems,
            )
        gains = Gains.from_mapping(data, source=f"gain set {name!r}")
        self.save(name, gains)
        return gains

    def load(self, name: str) -> Gains:
        path = self._path(name)
        if not path.is_file():
            raise GainSetError(f"no gain set named {name!r}")
        return load_gains_file(path)
