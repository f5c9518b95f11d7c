"""The suite's groups for pytest-xdist (tests/conftest.py): a test that shares a module-scoped
fixture is in its module's group, a test alone is in none, and under ``--dist loadgroup`` the
group is in the node id the scheduler groups by (``nodeid@group``), whatever the pytest."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def shared() -> list:
    return []


def test_a_test_sharing_a_module_fixture_is_in_its_modules_group(shared, request):
    mark = request.node.get_closest_marker("xdist_group")
    assert mark is not None and mark.args == (__name__,)
    if getattr(request.config.option, "loadgroup", False):  # a worker of --dist loadgroup
        assert request.node.nodeid.endswith(f"@{__name__}"), request.node.nodeid


def test_a_test_alone_is_in_no_group(request):
    assert request.node.get_closest_marker("xdist_group") is None
    assert "@" not in request.node.nodeid


def test_the_browser_and_rig_tiers_are_marked_and_the_quick_tier_leaves_them_out():
    """``-m "not browser and not rig"`` (docs/architecture.md) is the suite without chromium
    and the real-time rig: conftest marks each test that uses the ``browser`` fixture or flies
    the rig."""
    files = [
        "tests/test_dashboard_status.py",
        "tests/test_sitl_faults.py",
        "tests/test_suite_groups.py",
    ]

    cmd = [sys.executable, "-m", "pytest", "--collect-only", "-q", "-n", "0"]
    cmd += ["-p", "no:cacheprovider", "-m", "browser or rig", *files]
    out = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=False).stdout
    ids = [line for line in out.splitlines() if "::" in line]
    assert {i.split("::")[0] for i in ids} == set(files[:2]), out
    assert len(ids) == 6  # the five status tests (a browser each) and the one faults sortie
