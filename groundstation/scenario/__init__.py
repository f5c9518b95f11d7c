"""Scenario files (TOML): strict loading into typed dataclasses.

Every section is a dataclass (specs.py); its fields are the allowed keys, fields without a
default are required, and the annotation gives the type. An unknown key, a missing required
key, a wrong type or an impossible value raises :class:`ScenarioError` naming the file and the
key (problems.py). loading.py parses a file, validate.py checks its values (with physics.py's
balloon and fan-jet physics), overrides.py applies ``--set`` values and writes TOML back.
Angles are degrees in the file and stay so named (``yaw_deg``); they are converted where used.
"""

from .loading import load_scenario, parse_scenario, shipped_scenarios, with_changes
from .overrides import parse_overrides, scenario_toml, with_overrides
from .physics import (
    AIR_DENSITY_KG_M3,
    HELIUM_DENSITY_KG_M3,
    balloon_lift_and_mass,
    helium_gross_lift_n,
    jet_reference_problem,
)
from .problems import ScenarioError, ScenarioProblem
from .specs import (
    CAMERA_MODES,
    ESTIMATE_PROFILES,
    MOTIONS,
    SCENARIO_DIR,
    WIND_MODELS,
    BeliefSpec,
    CameraSpec,
    EstimateSpec,
    InterceptorSpec,
    Scenario,
    SimSpec,
    TargetSpec,
    Vec3,
    WindSpec,
)

__all__ = [
    "AIR_DENSITY_KG_M3",
    "CAMERA_MODES",
    "ESTIMATE_PROFILES",
    "HELIUM_DENSITY_KG_M3",
    "MOTIONS",
    "SCENARIO_DIR",
    "WIND_MODELS",
    "BeliefSpec",
    "CameraSpec",
    "EstimateSpec",
    "InterceptorSpec",
    "Scenario",
    "ScenarioError",
    "ScenarioProblem",
    "SimSpec",
    "TargetSpec",
    "Vec3",
    "WindSpec",
    "balloon_lift_and_mass",
    "helium_gross_lift_n",
    "jet_reference_problem",
    "load_scenario",
    "parse_overrides",
    "parse_scenario",
    "scenario_toml",
    "shipped_scenarios",
    "with_changes",
    "with_overrides",
]
