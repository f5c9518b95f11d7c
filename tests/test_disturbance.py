"""The disturbance observer (onboard/control/disturbance.py) and its feed-forward in the loop."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from onboard.camera_model import CameraModel
from onboard.control.attitude import attitude_command
from onboard.control.disturbance import (
    DisturbanceObserver,
    DisturbanceObserverConfig,
    feedforward_accel,
)
from onboard.datatypes import GRAVITY_M_S2, VehicleParams, VehicleState
from onboard.gains import Gains
from onboard.geometry import attitude_from_yaw_pitch_roll, quat_to_rotmat, rotmat_to_quat
from onboard.loop import InterceptionLoop

PARAMS = VehicleParams()  # 1.5 kg, thrust-to-weight 3
DT = 0.01
TAU_T = 0.03


def _fly(
    d_true,
    w=2.0,
    duration_s=4.0,
    noise_m_s=0.0,
    lag_ticks=0,
    manoeuvre=False,
    drag=0.0,
    seed=0,
    step_at_s=None,
):
    """A point-mass vehicle whose thrust follows the command through the motors' lag and whose
    thrust axis follows a commanded tilt through a first-order attitude lag (40 ms), fed to the
    observer as the loop would (velocity with seeded noise and lag). Returns times, d^ rows."""
    rng = np.random.default_rng(seed)
    obs = DisturbanceObserver(
        DisturbanceObserverConfig(w, PARAMS.mass_kg, PARAMS.max_thrust_n, drag_per_mass_1_s=drag)
    )
    m, g = PARAMS.mass_kg, GRAVITY_M_S2
    v = np.zeros(3)
    z = np.array([0.0, 0.0, 1.0])
    thrust = m * g
    sub = 10
    history: list[np.ndarray] = []
    ts, ds = [], []
    for k in range(int(duration_s / DT)):
        t = k * DT
        v_meas = v + noise_m_s * rng.standard_normal(3)
        history.append(v_meas)
        seen = history[max(len(history) - 1 - lag_ticks, 0)]
        ts.append(t)
        ds.append(obs.update(t, seen, z).copy())
        # command: hover, or a 2 m/s^2 weave in x and y (what PN asks) at 1 Hz
        a_cmd = np.zeros(3)
        if manoeuvre:
            a_cmd = 2.0 * np.array([math.sin(2 * math.pi * t), math.cos(2 * math.pi * t), 0.0])
        f = a_cmd + np.array([0.0, 0.0, g])
        z_cmd = f / np.linalg.norm(f)
        t_cmd = m * float(z @ f)
        t_cmd = min(max(t_cmd, 0.0), PARAMS.max_thrust_n)
        obs.commanded(t_cmd / PARAMS.max_thrust_n)
        d_now = np.asarray(d_true, float)
        if step_at_s is not None and t < step_at_s:
            d_now = np.zeros(3)
        h = DT / sub
        for _ in range(sub):
            thrust += (t_cmd - thrust) * (1 - math.exp(-h / TAU_T))
            z = z + (z_cmd - z) * (1 - math.exp(-h / 0.04))
            z = z / np.linalg.norm(z)
            v = v + ((thrust / m) * z - np.array([0, 0, g]) - drag * v + d_now) * h
    return np.array(ts), np.array(ds)


def test_converges_to_a_constant_disturbance_from_a_cold_start():
    d = np.array([0.8, -0.4, 0.2])
    ts, ds = _fly(d, w=2.0, duration_s=2.0)
    # growing-memory start: within 0.05 m/s^2 after 1 s (5.8 / w would be 2.9 s)
    assert np.all(np.linalg.norm(ds[ts >= 1.0] - d, axis=1) < 0.05)
    assert_allclose(ds[-1], d, atol=0.01)


def test_tracks_a_step_within_its_bandwidth():
    d = np.array([1.2, 0.0, 0.0])
    ts, ds = _fly(d, w=2.0, duration_s=6.0, step_at_s=2.0)
    assert np.linalg.norm(ds[ts < 2.0], axis=1).max() < 1e-6
    # w^2 / (s + w)^2: 2 % of a step left after 5.8 / w = 2.9 s
    after = ds[ts >= 2.0 + 3.0]
    assert np.all(np.abs(after[:, 0] - 1.2) < 0.02 * 1.2 + 0.01)


def test_rejects_velocity_noise_and_lag():
    d = np.array([1.0, 0.0, 0.0])
    # the state estimate's order: sigma 0.05 m/s, 20 ms lag (seeded)
    ts, ds = _fly(d, w=2.0, duration_s=8.0, noise_m_s=0.05, lag_ticks=2, seed=7)
    err = ds[ts >= 3.0] - d
    # module doc: sigma_d ~ sigma_v w sqrt(w T) / 2 = 0.007 m/s^2 per axis
    assert np.std(err, axis=0).max() < 0.015
    assert np.abs(err.mean(axis=0)).max() < 0.01


def _gnss_velocity_error(n: int, sigma_m_s: float, tau_s: float, seed: int) -> np.ndarray:
    """A first-order Gauss-Markov error per tick (the simulator's outdoor velocity error)."""
    rng = np.random.default_rng(seed)
    a = math.exp(-DT / tau_s)
    q = sigma_m_s * math.sqrt(1.0 - a * a)
    e = np.zeros(n)
    for k in range(1, n):
        e[k] = a * e[k - 1] + q * rng.standard_normal()
    return e


def _d_hat_std(w: float, err: np.ndarray) -> float:
    """The standard deviation (m/s^2) of d^ in hover with ``err`` as the velocity estimate."""
    obs = DisturbanceObserver(DisturbanceObserverConfig(w, PARAMS.mass_kg, PARAMS.max_thrust_n))
    out = []
    for k, e in enumerate(err):
        obs.commanded(PARAMS.mass_kg * GRAVITY_M_S2 / PARAMS.max_thrust_n)
        out.append(obs.update_floats(k * DT, (float(e), 0.0, 0.0), (0.0, 0.0, 1.0))[0])
    return float(np.std(out[1000:]))


def test_a_gnss_velocity_error_reaches_d_hat_in_proportion_to_the_bandwidth():
    # sigma 0.15 m/s correlated over 1 s (outdoor-gnss's middle): its changes are white at the
    # observer's frequencies, so d^ = w^2 s / (s + w)^2 of it grows about as w (faster below
    # the error's corner, 1 rad/s)
    err = _gnss_velocity_error(5000, 0.15, 1.0, seed=3)
    at_default = _d_hat_std(Gains().k_dob, err)
    assert Gains().k_dob == 2.0
    assert at_default == pytest.approx(0.10, abs=0.015)
    assert _d_hat_std(1.0, err) == pytest.approx(0.5 * at_default, rel=0.15)
    assert _d_hat_std(0.5, err) < 0.25 * at_default


def test_manoeuvres_do_not_leak_into_the_estimate():
    ts, ds = _fly(np.zeros(3), w=2.0, duration_s=5.0, manoeuvre=True, drag=0.17)
    # the attitude and thrust lag are in the model (measured axis, lagged thrust): no leak
    assert np.linalg.norm(ds[ts >= 1.0], axis=1).max() < 0.05


def test_own_drag_in_the_model_leaves_only_the_wind():
    wind = np.array([3.0, 0.0, 0.0])
    # drag -c (v - w) = -c v + c w: with c in the model, d^ is c w
    _ts, ds = _fly(0.17 * wind, w=2.0, duration_s=4.0, manoeuvre=True, drag=0.17)
    assert_allclose(ds[-1], 0.17 * wind, atol=0.02)


def test_non_finite_inputs_never_make_nan_and_hold_the_estimate():
    obs = DisturbanceObserver(DisturbanceObserverConfig(3.0, 1.5, 44.0))
    z = np.array([0.0, 0.0, 1.0])
    for k in range(50):
        obs.commanded(1.5 * GRAVITY_M_S2 / 44.0)
        obs.update(k * DT, np.array([0.01 * k, 0.0, 0.0]), z)
    held = obs.estimate_m_s2.copy()
    assert np.linalg.norm(held) > 0.1
    bad = [
        (0.5, np.array([math.nan, 0.0, 0.0]), z),
        (0.51, np.array([math.inf, 0.0, 0.0]), z),
        (math.nan, np.zeros(3), z),
        (0.52, np.zeros(3), np.array([0.0, math.nan, 1.0])),
        (0.53, np.zeros(3), np.zeros(3)),
        (0.49, np.zeros(3), z),  # time going back
    ]
    for t, v, zz in bad:
        obs.commanded(math.nan)
        obs.commanded(math.inf)
        out = obs.update(t, v, zz)
        assert np.all(np.isfinite(out))
        assert_allclose(out, held)


def test_clamp_and_reset():
    obs = DisturbanceObserver(DisturbanceObserverConfig(5.0, 1.5, 44.0, max_m_s2=1.0))
    z = np.array([0.0, 0.0, 1.0])
    for k in range(100):  # hover thrust, velocity growing at 4 m/s^2: d = 4 m/s^2
        obs.commanded(1.5 * GRAVITY_M_S2 / 44.0)
        obs.update(k * DT, np.array([0.04 * k, 0.0, 0.0]), z)
    assert math.isclose(float(np.linalg.norm(obs.estimate_m_s2)), 1.0, rel_tol=1e-9)
    before = obs.estimate_m_s2.copy()
    obs.update(100 * DT, np.array([50.0, 0.0, 0.0]), z)  # an estimator reset: a 46 m/s jump
    assert obs.resets == 1
    assert_allclose(obs.estimate_m_s2, before)


@pytest.mark.parametrize(
    "field, value",
    [("bandwidth_rad_s", -1.0), ("mass_kg", 0.0), ("max_m_s2", math.nan), ("start_factor", -1)],
)
def test_bad_config_is_refused(field, value):
    kw = dict(bandwidth_rad_s=2.0, mass_kg=1.5, max_thrust_n=44.0)
    kw[field] = value
    with pytest.raises(ValueError, match=field):
        DisturbanceObserverConfig(**kw)


def test_feedforward_is_normal_to_the_velocity_in_flight_and_full_in_hover():
    d = np.array([1.0, 2.0, 0.0])
    assert_allclose(feedforward_accel(d, np.array([0.0, 0.2, 0.0]), 0.5), -d)
    ff = feedforward_accel(d, np.array([0.0, 5.0, 0.0]), 0.5)
    assert_allclose(ff, [-1.0, 0.0, 0.0])
    half = feedforward_accel(d, np.array([0.0, 0.75, 0.0]), 0.5)  # halfway through the fade
    assert_allclose(half, [-1.0, -1.0, 0.0])


Q_NORTH = rotmat_to_quat(attitude_from_yaw_pitch_roll(math.pi / 2))


def _state(t, vel):
    return VehicleState(t, np.array([0.0, 0.0, 10.0]), np.array(vel), Q_NORTH, np.zeros(3))


def test_k_dob_zero_is_the_loop_without_observer():
    """k_dob = 0 and no believed drag (k_drag = 0): the command is exactly the attitude loop's
    on the guidance's a_d."""
    loop = InterceptionLoop(CameraModel(), PARAMS, Gains(k_dob=0.0, k_drag=0.0))
    for k in range(30):
        st = _state(k * DT, (0.05 * k, 3.0, 0.0))  # speeding sideways: d != 0
        tel = loop.tick(st)
        R_WB = quat_to_rotmat(Q_NORTH)
        omega, thrust = attitude_command(tel.accel_desired_enu_m_s2, R_WB, 0.0, loop.gains, PARAMS)
        assert np.array_equal(tel.command.body_rates_flu_rad_s, omega)
        assert tel.command.thrust_normalised == thrust
    assert not np.any(loop.disturbance.estimate_m_s2)


def test_loop_feeds_the_estimate_forward_while_holding():
    """Holding while something pushes the vehicle +x (the scripted velocity grows whatever is
    commanded): the observer sees a +x push and the loop leans against it; all finite."""
    loop = InterceptionLoop(CameraModel(), PARAMS, Gains(k_dob=3.0))
    off = InterceptionLoop(CameraModel(), PARAMS, Gains(k_dob=0.0))
    for k in range(200):
        st = _state(k * DT, (0.002 * k, 0.0, 0.0))  # drifting +x at 0.2 m/s^2
        tel = loop.tick(st)
        ref = off.tick(st)
        assert np.all(np.isfinite(tel.command.body_rates_flu_rad_s))
    d_hat = loop.disturbance.estimate_m_s2
    assert np.all(np.isfinite(d_hat)) and d_hat[0] > 0.1 and abs(d_hat[1]) < 0.01
    # both lean toward -x (braking); with the observer by d^ more, below the rate limit
    roll, roll_ref = tel.command.body_rates_flu_rad_s[0], ref.command.body_rates_flu_rad_s[0]
    assert abs(roll) < loop.gains.omega_max
    assert abs(roll) > abs(roll_ref) + 0.05
