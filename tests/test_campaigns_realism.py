"""Campaigns that draw what the vehicle cannot know per sortie (the airframe's drag, a wrong
believed target size) while the loop is configured only from what it believes."""

import numpy as np
import pytest

from groundstation.campaigns.definitions import (
    DRAG_RANGE_N_S_M,
    DRAG_SCENARIOS,
    SIZE_ERROR,
    get_campaign,
)
from groundstation.sim.simulation import Simulation


def test_every_sortie_draws_its_own_drag_in_the_range_and_the_loop_keeps_its_belief():
    jobs = get_campaign("drag").build(4, ("png", "pg"), "projected", 0)
    assert len(jobs) == len(DRAG_SCENARIOS) * 2 * 4
    assert {dict(j.labels)["scenario"] for j in jobs} == set(DRAG_SCENARIOS)
    drags = []
    for job in jobs:
        assert job.scenario.name == dict(job.labels)["scenario"]
        sim = Simulation(job.scenario, job.law, job.seed, keep_records=False)
        drags.append(sim.vehicle.drag_equivalent_n_s_m())
        assert sim.loop.gains.k_drag == job.scenario.gains_obj().k_drag  # the operator's belief
    lo, hi = DRAG_RANGE_N_S_M
    assert lo <= min(drags) and max(drags) <= hi
    assert np.ptp(drags) > 0.1  # drawn per sortie, not one value


def test_size_campaign_flies_the_static_targets_with_a_wrong_believed_size_per_target():
    static = get_campaign("static").build(6, ("png",), "projected", 3)
    jobs = get_campaign("size").build(6, ("png",), "projected", 3)
    factors = []
    for job, same in zip(jobs, static, strict=True):
        assert job.scenario.target == same.scenario.target  # the truth is the static campaign's
        believed = job.scenario.belief.target_diameter_m
        factor = dict(job.labels)["believed_over_true"]
        assert believed == pytest.approx(factor * job.scenario.target.diameter_m, rel=1e-3)
        assert 1 - SIZE_ERROR <= factor <= 1 + SIZE_ERROR
        sim = Simulation(job.scenario, job.law, job.seed, keep_records=False)
        assert sim.loop.dkf.config.target_diameter_m == believed  # the loop gets the belief
        factors.append(factor)
    assert min(factors) < 0.95 and max(factors) > 1.05  # both ways wrong among six
