"""The airframe and the air (docs/air.md): drag on the air-relative velocity and the speed
ramp that overcomes it, the turbulence field, light targets in the air (free balloon, buffet,
rotor wash) and the ground under kinematic targets."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from groundstation.scenario import TargetSpec, WindSpec, load_scenario, with_overrides
from groundstation.sim.physics import L_DISC, rotor_wash_at
from groundstation.sim.simulation import Simulation
from groundstation.sim.targets import Target
from groundstation.sim.vehicle import Multicopter
from groundstation.sim.wind import Wind
from onboard.datatypes import GRAVITY_M_S2

from .as_written import load_as_written

DT = 1.0 / 600.0


# ------------------------------------------------------------------ airframe
def test_airframe_drag_is_body_plus_rotor_on_the_air_relative_velocity():
    """Level at hover thrust, 10 m/s through the air: deceleration = (rotor + 0.5 rho C_d A
    |v_a|) v_a / m; a wind blowing with the vehicle at its speed leaves no drag; climbing
    straight up (air along the thrust axis) only the body drag acts."""
    spec = load_scenario("fast-crossing-50m").interceptor
    veh = Multicopter(spec)
    veh.v = [0.0, 10.0, 0.0]
    veh.step(DT, (0.0, 0.0, 0.0))
    drag = (0.2 + 0.5 * 1.2 * 0.02 * 10.0) * 10.0 / 1.5
    assert veh.accel[1] == pytest.approx(-drag, rel=1e-3)
    assert veh.drag_equivalent_n_s_m() == pytest.approx(0.32)
    still = Multicopter(spec)
    still.v = [0.0, 10.0, 0.0]
    still.step(DT, (0.0, 10.0, 0.0))
    assert still.accel[1] == pytest.approx(0.0, abs=1e-9)
    up = Multicopter(spec)
    up.v = [0.0, 0.0, 5.0]
    up.step(DT, (0.0, 0.0, 0.0))
    assert up.accel[2] == pytest.approx(-0.5 * 1.2 * 0.02 * 25.0 / 1.5, rel=1e-3)


def test_drawn_drag_stays_in_its_range_and_the_loop_believes_only_its_gain():
    sc = with_overrides(
        load_scenario("fast-crossing-50m"),
        {"interceptor.drag_min_n_s_m": 0.25, "interceptor.drag_max_n_s_m": 0.5},
    )
    drags = []
    for seed in range(8):
        sim = Simulation(sc, "png", seed, keep_records=False)
        drags.append(sim.vehicle.drag_equivalent_n_s_m())
        assert sim.loop.gains.k_drag == sc.gains_obj().k_drag  # the operator's belief
    assert min(drags) >= 0.25 and max(drags) <= 0.5
    assert max(drags) - min(drags) > 0.1  # drawn, not fixed
    assert len({round(d, 9) for d in drags}) == len(drags)


@pytest.mark.parametrize("name, v_max", [("fast-crossing-50m", 12.0), ("climbing-turn", 8.0)])
@pytest.mark.parametrize("drag", [0.25, 0.5])
def test_speed_ramp_reaches_v_max_against_the_drag_and_hits(name, v_max, drag):
    """The loop believes k_drag = 0.17 1/s (0.25 N s/m); the airframe's drag at 10 m/s is
    0.25 or 0.5 N s/m-equivalent: the ramp's feed-forward plus the observer's along-track part
    bring the vehicle within 0.6 m/s of v_max by the pass, and it hits. Flown with ideal
    sensors (tests/as_written.py) so that the airframe alone is tested."""
    sc = with_overrides(
        load_as_written(name),
        {"interceptor.drag_min_n_s_m": drag, "interceptor.drag_max_n_s_m": drag},
    )
    res = Simulation(sc, "png", 3, keep_records=False).run()
    assert res.outcome == "HIT", res
    assert res.terminal_speed_m_s == pytest.approx(v_max, abs=0.6), res


# ------------------------------------------------------------------ turbulence
def _field_samples(wind: Wind, points, times):
    out = np.zeros((len(times), len(points), 3))
    for i, t in enumerate(times):
        wind.params[6] = t
        for j, p in enumerate(points):
            out[i, j] = wind.at(p)
    return out


GUSTY = WindSpec(mean_m_s=(3.0, 0.0, 0.0), gust_m_s=1.0, turbulence_length_m=10.0)


def test_turbulence_is_correlated_near_and_not_far():
    """Two points 1 m apart across the wind see much the same gusts (correlation > 0.75; von
    Karman's transverse correlation there is about 0.85 for L = 10 m),
    two points 50 m apart (5 length scales) nearly independent ones (|corr| < 0.2)."""
    wind = Wind(GUSTY, np.random.default_rng(11))
    times = np.arange(0.0, 3000.0, 1.0)  # 9 km of field past the points
    s = _field_samples(wind, [(0, 0, 10), (0, 1, 10), (0, 50, 10)], times)
    near = np.corrcoef(s[:, 0, 0], s[:, 1, 0])[0, 1]
    far = np.corrcoef(s[:, 0, 0], s[:, 2, 0])[0, 1]
    assert near > 0.75 and abs(far) < 0.2, (near, far)


def test_turbulence_has_its_configured_intensity_and_is_seeded():
    wind = Wind(GUSTY, np.random.default_rng(12))
    times = np.arange(0.0, 4000.0, 1.0)
    s = _field_samples(wind, [(0, 0, 10)], times)[:, 0]
    assert s[:, 0].mean() == pytest.approx(3.0, abs=0.1)
    assert np.std(s[:, 0]) == pytest.approx(1.0, rel=0.1)
    assert np.std(s[:, 1]) == pytest.approx(1.0, rel=0.1)
    assert np.std(s[:, 2]) == pytest.approx(0.3, rel=0.1)
    again = Wind(GUSTY, np.random.default_rng(12))
    assert again.at((5.0, 6.0, 7.0)) == Wind(GUSTY, np.random.default_rng(12)).at((5.0, 6.0, 7.0))
    assert again.at((5.0, 6.0, 7.0)) != Wind(GUSTY, np.random.default_rng(13)).at((5.0, 6.0, 7.0))


def test_turbulence_sums_its_modes_in_order_as_the_compiled_kernel_does():
    """The kernel evaluates all modes at once (numpy as plain Python) and sums them in order,
    as its compiled form does: bit for bit the sum taken mode after mode (seeded modes, times
    and points; none past the modes given, none without modes)."""
    from groundstation.sim.physics import W_NMODES, W_SIZE, W_TIME, turbulence_at
    from groundstation.sim.wind import turbulence_modes

    rng = np.random.default_rng(21)
    for i in range(50):
        modes = turbulence_modes(rng, float(rng.uniform(1.0, 50.0)), int(rng.integers(1, 100)))
        c = rng.normal(0.0, 2.0, W_SIZE)
        c[W_TIME] = rng.uniform(0.0, 60.0)
        c[W_NMODES] = [len(modes), len(modes) + 5, 1, 0][i % 4]
        p = rng.normal(0.0, 20.0, 3)
        q = p - c[0:3] * c[W_TIME]
        g = [0.0, 0.0, 0.0]
        for m in modes[: int(c[W_NMODES])]:
            th = m[0] * q[0] + m[1] * q[1] + m[2] * q[2]
            for k in range(3):
                g[k] += m[3 + k] * math.cos(th) + m[6 + k] * math.sin(th)
        want = [c[3 + k] * g[k] for k in range(3)]
        assert [float(v) for v in turbulence_at(c, modes, *p)] == want, i


def test_vehicle_and_target_feel_the_same_field():
    sc = load_scenario("outdoor-static")
    sim = Simulation(sc, "png", 2, keep_records=False)
    for _ in range(30):
        sim.step_control_period()
    p = sim.vehicle.p
    w = sim.wind.at(p)
    assert w != sim.wind.at((p[0] + 60.0, p[1], p[2]))  # varies in space
    assert w != pytest.approx(sc.wind.mean_m_s, abs=1e-6)


# ------------------------------------------------------------------ light targets
def _balloon(**kw) -> Target:
    spec = TargetSpec(motion="balloon", position_m=(0.0, 0.0, 5.0), diameter_m=0.16, **kw)
    return Target(spec)


def test_free_balloon_drifts_with_a_gust():
    """A free 0.16 m balloon in still air, then a 2 m/s gust: within 3 s it moves with it."""
    b = _balloon(buffet_lift_coefficient=0.0)
    t = 0.0
    for _ in range(600):
        t += DT
        b.advance(t, DT, (0.0, 0.0, 0.0))
    assert abs(b.v[0]) < 1e-9 and b.v[2] > 0.5  # rises at its terminal speed, no drift
    x0 = b.p[0]
    for _ in range(1800):
        t += DT
        b.advance(t, DT, (2.0, 0.0, 0.0))
    assert b.v[0] == pytest.approx(2.0, abs=0.1)
    assert b.p[0] - x0 > 4.0


def test_buffet_frequency_is_strouhal():
    """A tethered balloon in a steady 4 m/s wind sways across it at St V / D = 5 Hz (FFT peak
    within 10 %); without the buffet it does not sway."""
    sc = load_scenario("indoor-tethered-wind-4")
    sways = {}
    for cl in (0.1, 0.0):
        spec = dataclasses.replace(sc.target, buffet_lift_coefficient=cl)
        b = Target(spec, np.random.default_rng(1))
        b.settle_in_wind(lambda p: (4.0, 0.0, 0.0))
        vy = []
        for k in range(1, 6001):
            b.advance(k * DT, DT, (4.0, 0.0, 0.0))
            vy.append(b.v[1])
        sways[cl] = np.array(vy[1200:])
    vy = sways[0.1] - sways[0.1].mean()
    spectrum = np.abs(np.fft.rfft(vy * np.hanning(len(vy))))
    freqs = np.fft.rfftfreq(len(vy), DT)
    peak = freqs[1:][np.argmax(spectrum[1:])]
    assert peak == pytest.approx(0.2 * 4.0 / 0.16, rel=0.1)
    assert np.std(sways[0.1]) > 0.01 and np.std(sways[0.0]) < 1e-6


def test_rotor_wash_pushes_a_balloon_below_the_vehicle_down():
    """A 1.5 kg vehicle hovering level 1.5 m above a free balloon: the wash there is the fully
    developed slipstream, 2 sqrt(T / (2 rho A)) downward (momentum theory); nothing above the
    rotors; weaker far below; the balloon, which would rise, is pushed down."""
    veh = Multicopter(load_scenario("fast-crossing-50m").interceptor)
    veh.p = [0.0, 0.0, 6.5]
    lag = veh.lag(DT)
    v_h = math.sqrt(1.5 * GRAVITY_M_S2 / (2.0 * 1.2 * lag[L_DISC]))
    below = rotor_wash_at(veh.x, lag, 0.0, 0.0, 0.0, 0.0, 0.0, 5.0)
    assert below == pytest.approx((0.0, 0.0, -2.0 * v_h), abs=1e-6)
    assert rotor_wash_at(veh.x, lag, 0.0, 0.0, 0.0, 0.0, 0.0, 7.5) == (0.0, 0.0, 0.0)
    assert abs(rotor_wash_at(veh.x, lag, 0.0, 0.0, 0.0, 0.0, 0.0, -3.5)[2]) < 0.4 * 2.0 * v_h
    b = _balloon(buffet_lift_coefficient=0.0)
    for k in range(1, 301):
        wash = rotor_wash_at(veh.x, lag, 0.0, 0.0, 0.0, *b.p)
        b.advance(k * DT, DT, wash)
    assert b.v[2] < -1.0 and b.p[2] < 5.0


# ------------------------------------------------------------------ the ground
def test_kinematic_target_never_goes_below_the_ground():
    """A CA target diving at 2 m/s^2 from 2 m: on the ground it stays at z = 0 with no
    downward velocity, its horizontal motion going on."""
    t = Target(
        TargetSpec(
            motion="ca",
            position_m=(0.0, 10.0, 2.0),
            velocity_m_s=(1.0, 0.0, 0.0),
            acceleration_m_s2=(0.0, 0.0, -2.0),
        )
    )
    for k in range(1, 3001):
        t.advance(k * DT, DT, (0.0, 0.0, 0.0))
        assert t.p[2] >= 0.0
    assert t.p[2] == 0.0 and t.v[2] == 0.0
    assert t.p[0] == pytest.approx(5.0, abs=1e-6)
