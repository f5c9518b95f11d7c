"""A start from the hover on an outdoor (GNSS-grade) state estimate: the loop flies along the
line of sight until its velocity estimate knows the velocity's direction (gain v_min)."""

import dataclasses

from groundstation.scenario import load_scenario
from groundstation.sim.simulation import run_sortie
from onboard.gains import Gains

# outdoor-static, seed 7: the drawn velocity error is 0.16 m/s a component (1 s correlation)
SEED = 7


def test_a_hovering_start_waits_for_a_known_velocity_direction_before_pn():
    sc = load_scenario("outdoor-static")  # realistic defaults: the outdoor-gnss profile
    assert Gains().v_min >= 1.0
    r = run_sortie(sc, "png", seed=SEED)
    assert r.outcome == "HIT" and r.miss_m < 0.10, r
    # at 0.5 m/s the estimate's noise is a third of the speed: PN turns it into the path
    early = dataclasses.replace(sc.gains_obj(), v_min=0.5)
    r_early = run_sortie(sc, "png", seed=SEED, gains=early)
    assert r_early.outcome == "MISS" and r_early.miss_m > 0.4, r_early
