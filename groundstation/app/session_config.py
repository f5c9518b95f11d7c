"""What a simulated sortie is flown with (the scenario, law, seed, camera mode and pace) and the
paces the operator can pick."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from onboard.enums import DEFAULT_LAW

from ..scenario import Scenario, with_changes

SPEEDS = {"1": 1.0, "2": 2.0, "5": 5.0, "max": math.inf}  # simulated seconds per wall second


@dataclass(frozen=True)
class SortieConfig:
    scenario: Scenario
    law: str = DEFAULT_LAW.value
    seed: int = 0
    camera: str = "projected"
    speed: str = "1"


def with_wind(scenario: Scenario, mean_m_s: tuple[float, float, float], gust_m_s: float):
    """The scenario with its wind's mean and gust replaced (validated); the model (uniform or
    a fan jet with its source) and the gust time constant are kept."""
    return with_changes(
        scenario,
        wind=dataclasses.replace(
            scenario.wind,
            mean_m_s=tuple(float(c) for c in mean_m_s),
            gust_m_s=float(gust_m_s),
        ),
    )
