"""The drag campaign: the two sorties that need the speed ramp to beat the airframe's drag,
each with its own drag drawn in the stated range while the loop believes only its gain."""

import numpy as np

from groundstation.campaigns.definitions import (
    DRAG_RANGE_N_S_M,
    DRAG_SCENARIOS,
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
