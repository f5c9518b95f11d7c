"""Wind models (groundstation/sim/wind.py) and the balloon's physics (scenario, targets)."""

import math

import numpy as np
import pytest

from groundstation.scenario import (
    ScenarioError,
    WindSpec,
    balloon_lift_and_mass,
    helium_gross_lift_n,
    load_scenario,
    with_overrides,
)
from groundstation.sim.simulation import Simulation
from groundstation.sim.wind import JET_DECAY_B, JET_SPREAD_S, Wind, jet_profile

JET = WindSpec(
    mean_m_s=(4.0, 0.0, 0.0), model="jet", jet_source_m=(-4.0, 0.0, 1.0), jet_diameter_m=0.4
)


def test_jet_profile_core_decay_and_spread():
    d = JET.jet_diameter_m
    assert jet_profile(JET, (-4.5, 0.0, 1.0)) == 0.0  # behind the fan
    assert jet_profile(JET, (-3.0, 0.0, 1.0)) == 1.0  # in the potential core (x < 5.8 D)
    x = 6.0
    assert math.isclose(jet_profile(JET, (-4.0 + x, 0.0, 1.0)), JET_DECAY_B * d / x)
    # half the centreline speed one half-width S x off the axis
    r_half = JET_SPREAD_S * x
    ratio = jet_profile(JET, (-4.0 + x, r_half, 1.0)) / jet_profile(JET, (-4.0 + x, 0.0, 1.0))
    assert math.isclose(ratio, 0.5, rel_tol=1e-9)


def test_jet_speed_is_set_at_the_reference_point():
    wind = Wind(JET, np.random.default_rng(0), reference_m=(0.0, 0.0, 1.0))
    assert wind.at((0.0, 0.0, 1.0)) == pytest.approx((4.0, 0.0, 0.0))
    assert wind.at((0.0, 3.0, 1.0)) == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)  # far off axis
    assert wind.at((4.0, 0.0, 1.0))[0] == pytest.approx(4.0 * 4.0 / 8.0)  # 1/x decay


def test_uniform_wind_without_gusts_is_the_same_everywhere_and_always():
    wind = Wind(WindSpec(mean_m_s=(3.0, 1.0, 0.0)), np.random.default_rng(5))
    assert wind.uniform and not wind.gusty
    first = wind.at((0.0, 0.0, 0.0))
    wind.step(10.0)
    assert first == wind.at((90.0, -40.0, 7.0)) == (3.0, 1.0, 0.0)


def test_balloon_physics_for_the_papers_balloon():
    target = load_scenario("indoor-tethered-wind-4").target
    assert helium_gross_lift_n(0.16) == pytest.approx(0.0218, abs=2e-4)
    lift, mass = balloon_lift_and_mass(target)
    assert lift == pytest.approx(0.0218 - 0.0015 * 9.80665, abs=2e-4)  # 0.0071 N
    assert mass == pytest.approx(0.0015 + 0.166 * 2.145e-3 + 0.6 * 2.145e-3, rel=0.01)  # 3.1 g


def test_bad_wind_and_balloon_values_are_refused():
    sc = load_scenario("indoor-tethered-wind-4")
    for sets, key in (
        ({"wind.model": "tornado"}, "wind.model"),
        ({"wind.jet_source_m": [3.0, 2.3, 1.0]}, "wind.jet_source_m"),  # downwind of the target
        ({"wind.jet_diameter_m": 0}, "wind.jet_diameter_m"),
        ({"target.envelope_mass_kg": 0.01}, "target.envelope_mass_kg"),  # too heavy to fly
        ({"target.net_lift_n": -0.1}, "target.net_lift_n"),
    ):
        with pytest.raises(ScenarioError) as err:
            with_overrides(sc, sets)
        assert [p.key for p in err.value.problems] == [key]
    # given values override the physics
    explicit = with_overrides(sc, {"target.net_lift_n": 0.03, "target.mass_kg": 0.015})
    assert balloon_lift_and_mass(explicit.target) == (0.03, 0.015)


def test_each_body_feels_the_jet_where_it_is():
    sim = Simulation(load_scenario("indoor-tethered-wind-4"), "png", seed=1)
    assert sim.wind.at(sim.vehicle.p) == pytest.approx((0.0, 0.0, 0.0), abs=1e-3)  # outside
    # the balloon leans downwind and down until its rope lies along lift + drag where it floats
    p = sim.target.p
    anchor = (0.5, 2.3, 0.4)
    rope = np.subtract(p, anchor)
    assert np.linalg.norm(rope) == pytest.approx(0.6)
    w = np.array(sim.wind.mean_at(p))
    lift, _ = balloon_lift_and_mass(sim.scenario.target)
    k = 0.5 * 1.2 * 0.47 * math.pi * 0.08**2
    force = k * np.linalg.norm(w) * w + np.array([0.0, 0.0, lift])
    assert np.cross(rope / 0.6, force / np.linalg.norm(force)) == pytest.approx(0.0, abs=0.02)
    assert p[0] > 0.9 and p[2] < 0.8
