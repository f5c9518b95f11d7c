"""What the README and docs/architecture.md say of the source's shape, held: ``onboard``
never imports ``groundstation``; the simulator flies the loop without the vehicle's runtime
(``onboard.runtime``: its threads, links and state machine); no source file is over 500
lines; every file the manual names by its path exists."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 500
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PATH_NAMED = re.compile(
    r"(?<![\w/.-])((?:onboard|groundstation|tests|web)/[\w/-]+\.(?:py|js|html|toml))"
)


def _sources(*folders: str) -> list[Path]:
    return sorted(p for f in folders for p in (ROOT / f).rglob("*.py"))


def _imports(path: Path) -> list[str]:
    """The modules ``path`` imports, absolute (a relative import resolved to its package)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                names.append(".".join([*base, node.module] if node.module else base))
            else:
                names.append(node.module or "")
    return names


def _offenders(paths: list[Path], forbidden: str) -> list[str]:
    return [
        f"{p.relative_to(ROOT)} imports {m}"
        for p in paths
        for m in _imports(p)
        if m == forbidden or m.startswith(forbidden + ".")
    ]


def test_onboard_never_imports_the_ground_station():
    assert _offenders(_sources("onboard"), "groundstation") == []


def test_the_simulator_flies_the_loop_without_the_vehicle_runtime():
    assert _offenders(_sources("groundstation/sim"), "onboard.runtime") == []


def test_the_import_check_finds_absolute_and_relative_imports():
    # the simulator imports onboard absolutely; the runtime's state machine imports the
    # track's module relatively (from ..track_loss)
    assert _offenders(_sources("groundstation/sim"), "onboard")
    relative = _offenders(_sources("onboard/runtime"), "onboard.track_loss")
    assert "onboard/runtime/state_machine.py imports onboard.track_loss" in relative


def test_no_source_file_is_over_500_lines():
    long = {
        str(p.relative_to(ROOT)): n
        for p in _sources("onboard", "groundstation", "tests")
        if (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert long == {}


def test_every_file_the_manual_names_exists():
    named = {(page.name, m) for page in PAGES for m in PATH_NAMED.findall(page.read_text())}
    assert len(named) > 20
    assert sorted((page, p) for page, p in named if not (ROOT / p).exists()) == []
