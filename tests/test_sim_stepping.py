"""The simulator's fast path (the physics steps between events in one kernel call) flies
exactly what stepping one physics step at a time flies."""

from __future__ import annotations

import numpy as np
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
    assert result.outcome in ("HIT", "MISS", "TIMEOUT", "TARGET_LOST", "CRASHED")


def test_a_stretch_in_one_kernel_call_steps_like_single_steps_with_a_command_mid_way():
    scenario = load_scenario("indoor-tethered-wind-4")  # jet, gusts, tethered balloon
    a, b = (Simulation(scenario, "png", 5, keep_records=False) for _ in range(2))
    rates = np.array([0.4, -0.3, 0.2])
    for sim in (a, b):
        sim._commands.append((3, rates, 0.7))  # arrives at step 3 of the 6
    a._physics_steps(0, 6)
    for k in range(6):
        b._physics_steps(k, 1)
    assert a.step_index == b.step_index == 6 and a.outcome is b.outcome is None
    assert a._physics.tobytes() == b._physics.tobytes()  # every state, bit for bit
    assert a.vehicle.cmd_w == b.vehicle.cmd_w == rates.tolist()
    # the vehicle's own step (SITL) is the same kernel: one more step either way agrees
    wind = a.wind.at(a.vehicle.p)
    c = Multicopter(scenario.interceptor)
    c.x[:] = a.vehicle.x
    a.vehicle.step(a.dt_s, wind)
    c.step(a.dt_s, wind)
    assert (c.p, c.v, c.q, c.w, c.thrust_n, c.accel) == (
        a.vehicle.p,
        a.vehicle.v,
        a.vehicle.q,
        a.vehicle.w,
        a.vehicle.thrust_n,
        a.vehicle.accel,
    )
    assert c.finite() and c.read_gyro() == a.vehicle.read_gyro()
