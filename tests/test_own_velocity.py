"""The own-velocity complementary filter (onboard/estimation/own_velocity.py) and what it does
for the SM tailgate's miss."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from groundstation.scenario import load_scenario
from groundstation.sim.simulation import Simulation
from onboard.constants import GRAVITY_M_S2
from onboard.estimation.own_velocity import OwnVelocityFilter
from onboard.gains import Gains

DT = 0.01  # the loop's tick (s)


def _gauss_markov(n: int, sigma: float, tau_s: float, seed: int) -> np.ndarray:
    """A first-order Gauss-Markov error sampled every DT (the simulator's velocity error)."""
    rng = np.random.default_rng(seed)
    a = math.exp(-DT / tau_s)
    b = sigma * math.sqrt(1.0 - a * a)
    e = np.empty(n)
    e[0] = sigma * rng.standard_normal()
    for i in range(1, n):
        e[i] = a * e[i - 1] + b * rng.standard_normal()
    return e


def _fly(tau_c: float, v_meas: np.ndarray, accel_model: np.ndarray) -> np.ndarray:
    """The filter's output along x for measured velocities and modelled accelerations."""
    f = OwnVelocityFilter(tau_c)
    out = np.empty(len(v_meas))
    for i, (v, a) in enumerate(zip(v_meas.tolist(), accel_model.tolist(), strict=True)):
        out[i] = f.update(DT, v, 0.0, 0.0)[0]
        f.set_accel(a, 0.0, 0.0)
    return out


def _accel_step(n: int, at_s: float, accel: float) -> tuple[np.ndarray, np.ndarray]:
    """A true acceleration step and the velocity it gives at each tick."""
    t = np.arange(n) * DT
    acc = np.where(t >= at_s, accel, 0.0)
    v = np.concatenate(([0.0], np.cumsum(acc)[:-1] * DT))
    return acc, v


def test_zero_time_constant_passes_the_velocity_through_to_the_bit():
    f = OwnVelocityFilter(0.0)
    f.set_accel(3.0, -2.0, 1.0)
    for v in ((1.0, 2.0, 3.0), (0.1 + 0.2, -7.25e-3, 1e-300), (5.0, 5.0, -5.0)):
        assert f.update(DT, *v) == v
    # switched on later, it starts from the last velocity, not a stale one
    f.set_time_constant(1.0)
    f.set_accel(0.0, 0.0, 0.0)
    assert f.update(DT, 5.0, 5.0, -5.0) == (5.0, 5.0, -5.0)


def test_it_removes_the_gnss_velocity_errors_wander_and_follows_a_modelled_step():
    # a 0.15 m/s, 1 s Gauss-Markov error (the outdoor profile's) on a vehicle that steps to
    # 3 m/s^2 at 15 s, the step in the modelled acceleration
    n = 3000
    err = _gauss_markov(n, 0.15, 1.0, seed=0)
    acc, v_true = _accel_step(n, 15.0, 3.0)
    out = _fly(3.0, v_true + err, acc) - v_true
    lag = 40  # 0.4 s: a burst of dropped frames
    raw_change = float(np.sqrt(np.mean((err[lag:] - err[:-lag]) ** 2)))
    filt_change = float(np.sqrt(np.mean((out[lag:] - out[:-lag]) ** 2)))
    assert raw_change == pytest.approx(0.121, abs=0.01)
    assert filt_change < 0.2 * raw_change  # 0.016 m/s
    assert float(np.std(np.diff(out))) < 0.05 * float(np.std(np.diff(err)))  # per tick
    # the modelled step is followed at once: the filter's error is what it would be with no
    # step at all, tick for tick
    flat = _fly(3.0, err, np.zeros(n))
    assert np.abs(out - flat).max() < 1e-9


def test_an_unmodelled_acceleration_leaves_a_bias_of_accel_times_tau():
    n = 2000
    _, v_true = _accel_step(n, 1.0, 0.3)  # the model misses it
    for tau_c in (0.5, 2.0):
        out = _fly(tau_c, v_true, np.zeros(n)) - v_true
        k = int((1.0 + 5.0 * tau_c) / DT)
        assert out[k:] == pytest.approx(-0.3 * tau_c, abs=0.01 * 0.3 * tau_c + 0.005 * 0.3)
        assert out[:100] == pytest.approx(0.0, abs=1e-12)


def test_a_reset_or_a_bad_input_restarts_at_the_measurement():
    f = OwnVelocityFilter(3.0)
    assert f.velocity_enu_m_s is None
    f.update(DT, 1.0, 0.0, 0.0)
    f.set_accel(math.nan, 0.0, 0.0)  # taken as 0
    assert f.update(DT, 1.3, 0.0, 0.0)[0] == pytest.approx(1.0 + 0.3 * -math.expm1(-DT / 3.0))
    out = f.update(DT, math.nan, 0.0, 0.0)  # handed on as it came, the state forgotten
    assert math.isnan(out[0]) and out[1:] == (0.0, 0.0)
    assert f.velocity_enu_m_s is None
    assert f.update(DT, 2.0, 1.0, 0.0) == (2.0, 1.0, 0.0)
    assert f.update(DT, 6.0, 1.0, 0.0) == (6.0, 1.0, 0.0)  # a 4 m/s jump: an estimator reset
    f.reset()
    assert f.update(DT, -1.0, 0.0, 0.0) == (-1.0, 0.0, 0.0)


@pytest.mark.parametrize("bad", [-0.1, math.nan, math.inf, "1"])
def test_a_bad_time_constant_is_refused_and_changes_nothing(bad):
    f = OwnVelocityFilter(1.0)
    with pytest.raises(ValueError, match="time constant"):
        f.set_time_constant(bad)
    assert f.tau_s == 1.0
    with pytest.raises(ValueError):
        OwnVelocityFilter(bad)


def test_the_sm_tailgate_sortie_the_velocity_error_spoils_is_closer_with_the_filter():
    # sm-tailgate, seed 17, realistic defaults: a burst of dropped frames ends 0.2 s before
    # the pass; with the estimate's own velocity the DKF's prediction through it drifts
    s = load_scenario("sm-tailgate")
    with_filter = Simulation(s, seed=17).run()
    without = Simulation(s, seed=17, gains=dataclasses.replace(Gains(), tau_vel=0.0)).run()
    assert Gains().tau_vel == 3.0
    assert without.miss_m == pytest.approx(0.084, abs=0.01)
    assert with_filter.miss_m == pytest.approx(0.019, abs=0.01)


def test_the_thrust_form_is_the_acceleration_the_loop_models():
    # hovering thrust along the vertical with no disturbance: no acceleration, v_f holds
    f = OwnVelocityFilter(3.0)
    f.update(DT, 1.0, 0.0, 0.0)
    f.set_thrust(GRAVITY_M_S2, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    assert f.update(DT, 1.0, 0.0, 0.0) == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)
    # tilted 30 deg towards +x at the thrust that holds the height, 0.5 m/s^2 of drag back
    c, s_ = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    f.set_thrust(GRAVITY_M_S2 / c, s_, 0.0, c, -0.5, 0.0, 0.0)
    ax = GRAVITY_M_S2 * s_ / c - 0.5
    out = f.update(DT, 1.0, 0.0, 0.0)
    assert out[0] == pytest.approx(1.0 + DT * ax * math.exp(-DT / 3.0), rel=1e-12)
    assert out[2] == pytest.approx(0.0, abs=1e-12)
