"""What `pip install .` ships: every package of the source tree, the scenarios and the pages.
(The tests import the checkout, so a package missing from the wheel would pass unnoticed.)"""

import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent


def test_every_package_in_the_tree_is_listed():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(cfg["packages"])
    in_tree = {
        ".".join(p.parent.relative_to(ROOT).parts)
        for top in ("onboard", "groundstation")
        for p in (ROOT / top).rglob("__init__.py")
    }
    assert in_tree <= listed, f"missing from pyproject packages: {sorted(in_tree - listed)}"
    assert cfg["package-dir"]["groundstation.web"] == "web"
    web_files = {p.name for p in (ROOT / "web").iterdir() if p.suffix in (".html", ".js", ".css")}
    assert {"index.html", "app.js", "sorties.html", "sorties.js", "style.css"} <= web_files
    assert "scenarios/*.toml" in cfg["package-data"]["groundstation"]
