"""Named state-estimate error profiles, drawn per sortie (docs/realism.md "Error profiles").

A profile gives, for each error of the state-estimate model (:mod:`.estimate`), a range; each
sortie draws its own value from every range, uniformly, from the sortie's seed, and the loop
never learns the draw. A key the scenario's ``[estimate]`` table sets to a value other than
its default is flown as written (the profile draws only what the scenario leaves open), so
``--set estimate.lag_s=0.05`` still means what it says.

``ideal`` hands the loop the truth (no estimate errors at all): for analysis only, and
labelled wherever a result is shown (:func:`label`).

Sources of the ranges:

- indoor-mocap: a motion-capture system (Vicon Vero/Vantage, OptiTrack Prime: sub-millimetre
  position, latency 3-10 ms at 100-360 Hz) fused by PX4's EKF2 as external vision
  (``EKF2_EV_*``); what the loop gets is EKF2's output, a few cm/s and tenths of a degree,
  20 ms old with the telemetry stream. Camera-IMU offset of an unsynchronised companion
  camera: a few ms (Kalibr-style calibrations).
- outdoor-gnss: PX4 EKF2 with a u-blox M8/M9 GNSS (``EKF2_GPS_V_NOISE`` 0.3 m/s, the fused
  velocity error 0.1-0.2 m/s), heading from the magnetometer 1-3 degrees (tilt stays a few
  tenths of a degree, held by the accelerometers), the estimate 20-60 ms old (GNSS delay
  ``EKF2_GPS_DELAY`` 110 ms compensated by the output predictor, the telemetry stream, the
  link), a companion camera with its time offset to the IMU up to +-35 ms uncalibrated, hover
  thrust known to 5 % (``MPC_THR_HOVER`` estimated in flight, battery sag).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..scenario import ESTIMATE_PROFILES, EstimateSpec, Scenario, with_changes

IDEAL = "ideal"
TABLE = "table"  # no draw: the [estimate] table as written


@dataclass(frozen=True)
class ErrorProfile:
    name: str
    summary: str
    ranges: dict[str, tuple[float, float]]  # EstimateSpec key -> (low, high), uniform

    def draw(self, spec: EstimateSpec, rng: np.random.Generator) -> EstimateSpec:
        """``spec`` with every key it leaves at its default drawn from this profile's range
        (one uniform number per key, in the ranges' order, whether used or not: the draws
        do not depend on which keys the scenario sets)."""
        defaults = EstimateSpec()
        changes = {}
        for key, (lo, hi) in self.ranges.items():
            value = float(rng.uniform(lo, hi))
            if getattr(spec, key) == getattr(defaults, key):
                changes[key] = value
        return dataclasses.replace(spec, **changes)


PROFILES: dict[str, ErrorProfile] = {
    p.name: p
    for p in (
        ErrorProfile(
            "indoor-mocap",
            "indoor motion capture: velocity 0.04-0.06 m/s, attitude 0.15-0.25 deg, lag 15-25 ms,"
            " camera-IMU offset sigma 5 ms, thrust 2 %",
            {
                "vel_noise_m_s": (0.04, 0.06),
                "pos_noise_m": (0.01, 0.05),
                "att_noise_deg": (0.15, 0.25),
                "heading_noise_deg": (0.15, 0.25),
                "lag_s": (0.015, 0.025),
                "camera_time_offset_s": (0.004, 0.006),
                "thrust_scale_sigma": (0.015, 0.025),
            },
        ),
        ErrorProfile(
            "outdoor-gnss",
            "outdoor GNSS/EKF2: velocity 0.1-0.2 m/s, heading 1-3 deg, tilt 0.2-0.5 deg, lag"
            " 20-60 ms (unknown to the loop), camera-IMU offset sigma 10-17.5 ms (up to"
            " +-35 ms), thrust 5 %",
            {
                "vel_noise_m_s": (0.1, 0.2),
                "pos_noise_m": (0.2, 0.5),
                "att_noise_deg": (0.2, 0.5),
                "heading_noise_deg": (1.0, 3.0),
                "lag_s": (0.02, 0.06),
                "camera_time_offset_s": (0.010, 0.0175),
                "thrust_scale_sigma": (0.05, 0.05),
            },
        ),
    )
}
PROFILE_NAMES = (*PROFILES, IDEAL, TABLE)
assert set(PROFILE_NAMES) == set(ESTIMATE_PROFILES)


def check_profile(name: str) -> str:
    """``name`` if it names a profile, else a ValueError listing them."""
    if name not in PROFILE_NAMES:
        raise ValueError(f"unknown estimate profile {name!r}; choose one of {PROFILE_NAMES}")
    return name


def with_profile(scenario: Scenario, name: str | None) -> Scenario:
    """The scenario flown with error profile ``name`` (None: as it is)."""
    if name is None:
        return scenario
    check_profile(name)
    return with_changes(scenario, estimate=dataclasses.replace(scenario.estimate, profile=name))


def profile_of(scenario: Scenario) -> str:
    """The profile a sortie of ``scenario`` flies: ``ideal`` whenever the loop sees the truth."""
    e = scenario.estimate
    return IDEAL if (not e.enabled or e.profile == IDEAL) else e.profile


def label(profile: str) -> str:
    """How a result names its profile: ideal sensors always say so."""
    return "ideal sensors (analysis only)" if profile == IDEAL else profile


def sortie_estimate(scenario: Scenario, seed: np.random.SeedSequence) -> EstimateSpec | None:
    """The estimate model's settings for one sortie (None: ideal sensors, the loop sees the
    truth): the scenario's profile drawn from ``seed``."""
    name = profile_of(scenario)
    if name == IDEAL:
        return None
    if name == TABLE:
        return scenario.estimate
    return PROFILES[name].draw(scenario.estimate, np.random.default_rng(seed))
