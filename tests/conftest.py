import math
import os

# The suite runs the kernels as Python (a newcomer's and the vehicle's mode) in this process and
# in every process it starts, whatever a command it runs in-process asks for; .ci/run checks the
# compiled kernels against their references apart (PEREGRINE_JIT=1).
os.environ.setdefault("PEREGRINE_JIT", "0")

import numpy as np
import pytest

from onboard.geometry import attitude_from_yaw_pitch_roll

# the browser tests' ground station and chromium, one of each per module, and their pages
from .browser_support import browser, page, station  # noqa: F401

_FUZZ: dict[str, tuple[int, int]] = {}  # suite -> (cases tried, failures)


@pytest.fixture
def fuzz_summary():
    """``record(suite, cases, failures)``: the fuzz totals the terminal summary prints."""

    def record(suite: str, cases: int, failures: int) -> None:
        _FUZZ[suite] = (cases, failures)

    return record


def pytest_sessionfinish(session) -> None:
    """Under pytest-xdist a worker hands its fuzz totals to the controller, which prints them."""
    out = getattr(session.config, "workeroutput", None)
    if out is not None:
        out["fuzz"] = {suite: list(totals) for suite, totals in _FUZZ.items()}


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error) -> None:
    for suite, (cases, failures) in getattr(node, "workeroutput", {}).get("fuzz", {}).items():
        _FUZZ[suite] = (cases, failures)


def _flies_the_rig(item) -> bool:
    """Does the test fly the SITL rig (the simulator standing in for PX4 and the onboard
    runtime, each a real-time process)? Its module or the test itself uses ``Rig``."""
    from .sitl_rig import Rig

    code = getattr(getattr(item, "function", None), "__code__", None)
    return getattr(item.module, "Rig", None) is Rig or (
        code is not None and "Rig" in code.co_varnames + code.co_names
    )


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items) -> None:
    """Groups for pytest-xdist (``--dist loadgroup``: a group runs on one worker, in file
    order). The tests that fly the SITL rig form one group, so two real-time rigs never share
    the two cores. Tests that share a module-scoped fixture (a ground station, a browser, a
    flown log) form one group per module: the fixture is made once, and a test that expects
    the state the previous ones left (the browser modules) finds it. Tests marked ``early``
    come first. The tiers (pyproject.toml's markers): a test that flies the rig is marked
    ``rig``, one that drives chromium (the ``browser`` fixture) ``browser``."""
    for item in items:
        rig = _flies_the_rig(item)
        info = getattr(item, "_fixtureinfo", None)
        if rig:
            item.add_marker(pytest.mark.rig)
        if info is not None and "browser" in info.names_closure:
            item.add_marker(pytest.mark.browser)
        if item.get_closest_marker("xdist_group") is not None:
            continue
        if rig:
            item.add_marker(pytest.mark.xdist_group("sitl-rig"))
            continue
        if info is None:
            continue
        shared = any(
            d.scope in ("module", "class", "package")
            for name in info.names_closure
            for d in info.name2fixturedefs.get(name, ())
        )
        if shared:
            item.add_marker(pytest.mark.xdist_group(item.module.__name__))
    # Longest first: xdist hands out the groups with the most tests first, then the rest in
    # this order; a long test left to the end would keep one worker busy while the other idles.
    items.sort(key=lambda item: item.get_closest_marker("early") is None)


class _GroupNames:
    """On a worker, after pytest-xdist has named each grouped test ``nodeid@group`` (the name
    its scheduler groups by): pytest-xdist writes that name to the item's ``_nodeid``, which
    pytest 9.2 no longer reads (a node id is the structured ``_id``), so the groups were
    silently spread over both workers. This puts the name where the running pytest reads it,
    and refuses to run when neither works: two SITL rigs on the two cores at once fail their
    timing."""

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, config, items) -> None:
        if not getattr(config.option, "loadgroup", False):
            return
        for item in items:
            names = sorted({str(m.args[0]) for m in item.iter_markers("xdist_group") if m.args})
            suffix = "@" + "_".join(names)
            if not names or item.nodeid.endswith(suffix):
                continue
            if hasattr(item, "_id"):
                from _pytest.nodeid import NodeId

                item._id = NodeId.parse(item.nodeid + suffix)
            if not item.nodeid.endswith(suffix):
                raise pytest.UsageError(
                    f"--dist loadgroup cannot group {item.nodeid} with this pytest and "
                    "pytest-xdist; run with -n 0"
                )


def pytest_configure(config) -> None:
    config.pluginmanager.register(_GroupNames(), "peregrine-xdist-group-names")


def pytest_terminal_summary(terminalreporter) -> None:
    if not _FUZZ:
        return
    terminalreporter.section("fuzz summary")
    for suite, (cases, failures) in sorted(_FUZZ.items()):
        terminalreporter.write_line(f"{suite}: {cases} cases tried, failures: {failures}")


@pytest.fixture
def R_north() -> np.ndarray:
    """Level vehicle facing +y (north)."""
    return attitude_from_yaw_pitch_roll(math.pi / 2)


@pytest.fixture
def gs(tmp_path):
    """A ground station in simulator mode with its data and logs under tmp_path."""
    from groundstation.app.server import GroundStation

    ground = GroundStation(port=0, data_dir=tmp_path, log_dir=tmp_path / "logs")
    yield ground
    ground.close()


@pytest.fixture
def client(gs):
    """An authorised HTTP client of ``gs``'s API (FastAPI's TestClient)."""
    from fastapi.testclient import TestClient

    with TestClient(gs.app, base_url="http://127.0.0.1") as c:
        c.headers["Authorization"] = f"Bearer {gs.token}"
        yield c
