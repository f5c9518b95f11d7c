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


def test_every_file_a_page_loads_is_shipped():
    """Each script and stylesheet the pages name (/static/...) is in web/ and matched by the
    package data's globs (a page split into parts loads every part from the wheel too)."""
    import fnmatch
    import re

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    globs = cfg["package-data"]["groundstation.web"]
    for page in (ROOT / "web").glob("*.html"):
        named = re.findall(r'(?:src|href)="/static/([^"]+)"', page.read_text())
        assert named, page.name
        for rel in named:
            assert (ROOT / "web" / rel).is_file(), (page.name, rel)
            assert any(fnmatch.fnmatch(rel, g) and rel.count("/") == g.count("/") for g in globs), (
                page.name,
                rel,
            )
