"""The simulator's fast path (physics steps between events in one call, the vehicle as a
generator) flies exactly what stepping one physics step at a time flies."""

from __future__ import annotations

import math

import pytest

from groundstation.scenario import load_scenario
from groundstation.sim.simulation import Simulation
from groundstation.sim.vehicle import Multicopter


def _state(sim: Simulation) -> tuple:
    veh = sim.vehicle
    return (
        sim.step_index,
        sim.outcome,
        sim.miss_m,
        sim.closest_time_s,
        sim.closest_speed_m_s,
        tuple(sim.closest_rel_m),
        tuple(sim.closest_vel_m_s),
        sim.max_normal_accel_m_s2,
        tuple(veh.p),
        tuple(veh.v),
        tuple(veh.q),
        tuple(veh.w),
        veh.thrust_n,
        tuple(sim.target.p),
    )


@pytest.mark.parametrize(
    "name",
    [
        "cv-top-to-bottom",  # moving target, estimate model (commands land between ticks)
        "indoor-tethered-wind-4",  # fan jet (wind where each body is), gusts, tethered balloon
        "outdoor-escape",  # uniform gusty wind, accelerating target
    ],
)
def test_run_flies_exactly_what_single_steps_fly(name):
    scenario = load_scenario(name)
    fast = Simulation(scenario, "png", 3, keep_records=False)
    result = fast.run()
    slow = Simulation(scenario, "png", 3, keep_records=False)
    while not slow.done:
        slow.step()
    assert slow.result() == result  # every field, bit for bit
    assert _state(slow) == _state(fast)
    assert result.outcome in ("HIT", "MISS", "TIMEOUT", "TARGET_LOST")


def test_vehicle_generator_steps_like_step_and_takes_commands_between_sends():
    spec = load_scenario("static-ahead-20m").interceptor
    a, b = Multicopter(spec), Multicopter(spec)
    dt, wind = 1.0 / 600.0, (0.5, -0.2, 0.1)
    steps = a.integrate(dt)
    steps.send(None)
    out = None
    for k in range(12):
        if k == 5:  # a command mid-way: both take it at the next step
            a.command([0.4, -0.3, 0.2], 0.7)
            b.command([0.4, -0.3, 0.2], 0.7)
        out = steps.send(wind)
        b.step(dt, wind)
    steps.close()  # writes the state back
    assert (a.p, a.v, a.q, a.w, a.thrust_n, a.accel) == (b.p, b.v, b.q, b.w, b.thrust_n, b.accel)
    assert out[:6] == (*b.p, *b.v)
    assert math.isfinite(out[6]) and b.finite()
    assert a.read_gyro() == b.read_gyro()  # the same 12 rates averaged
