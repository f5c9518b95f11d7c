import math

import numpy as np
import pytest

from onboard.geometry import attitude_from_yaw_pitch_roll

# the browser tests' ground station and chromium, one of each per module
from .browser_support import browser, station  # noqa: F401

_FUZZ: dict[str, tuple[int, int]] = {}  # suite -> (cases tried, failures)


@pytest.fixture
def fuzz_summary():
    """``record(suite, cases, failures)``: the fuzz totals the terminal summary prints."""

    def record(suite: str, cases: int, failures: int) -> None:
        _FUZZ[suite] = (cases, failures)

    return record


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
