"""The augmented law (onboard/control/apn.py): its command limit from the airframe, its term,
a pure kinematic intercept of a target accelerating at a constant rate, where linear theory
says APN needs at most N/2 a_T and PN up to N/(N - 2) a_T (Zarchan, ch. 8), and the
prediction of a target in a coordinated turn, whose acceleration turns with it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.constants import GRAVITY_M_S2
from onboard.control.apn import (
    MIN_TURN_SPEED_M_S,
    apn_law,
    apn_term,
    available_lateral_accel_m_s2,
    endgame_speed_cap_m_s,
    manoeuvre_accel_m_s2,
    time_to_go_s,
    turn_prediction_accel_m_s2,
    turn_speed_cap_m_s,
)
from onboard.control.guidance import GuidanceInput, direction_angles
from onboard.estimation.imm import MotionEstimate
from onboard.gains import Gains
from onboard.geometry import wrap_pi

G = GRAVITY_M_S2


def test_the_limit_comes_from_thrust_to_weight_and_tilt():
    # TW 3, 2 m/s^2 kept for the vertical: sqrt(29.43^2 - 11.81^2) = 26.96; tilt 45: g
    assert available_lateral_accel_m_s2(1 / 3, 80.0, 2.0) == pytest.approx(26.957, abs=1e-3)
    assert available_lateral_accel_m_s2(1 / 3, 45.0, 2.0) == pytest.approx(G, rel=1e-12)
    # TW 1.5 with nothing kept: g sqrt(1.5^2 - 1) = 1.118 g
    assert available_lateral_accel_m_s2(1 / 1.5, 80.0, 0.0) == pytest.approx(1.118 * G, rel=1e-3)
    assert available_lateral_accel_m_s2(0.95, 45.0, 2.0) == 0.0  # cannot even hold the margin
    with pytest.raises(ValueError, match="hover thrust"):
        available_lateral_accel_m_s2(0.0, 45.0, 2.0)


def test_the_term_is_half_n_times_the_acceleration_across_the_line_of_sight():
    los = (0.0, 1.0, 0.0)
    np.testing.assert_allclose(apn_term((3.0, 5.0, -1.0), los, 3.0), (4.5, 0.0, -1.5))


def _intercept(law_target_accel: bool, a_t: float, limit: float):
    """A point-mass interceptor flying its command exactly (no lag, perfect LOS) at 10 m/s
    toward a target 40 m ahead that accelerates at ``a_t`` m/s^2 east from rest; returns (miss
    m, the command's lateral (east) part over time, m/s^2)."""
    gains = Gains()
    dt = 0.01
    p, v = np.zeros(3), np.array([0.0, 10.0, 0.0])
    p_t0, a_vec = np.array([0.0, 20.0, 0.0]), np.array([a_t, 0.0, 0.0])
    prev = None
    miss, lateral = math.inf, []
    for k in range(600):
        t = k * dt
        p_t = p_t0 + 0.5 * a_vec * t * t
        r = p_t - p
        dist = float(np.linalg.norm(r))
        miss = min(miss, dist)
        if r @ (a_vec * t - v) > 0.0 and dist < 3.0:  # opening: passed
            break
        n = r / dist
        q_y, q_z = direction_angles(n)
        dq = (0.0, 0.0) if prev is None else (q_y - prev[0], wrap_pi(q_z - prev[1]))
        prev = (q_y, q_z)
        inp = GuidanceInput(
            dt, n, q_y, q_z, dq[0], dq[1], v.copy(), (0.0, 0.0), np.eye(3),
            target_accel_enu_m_s2=tuple(a_vec) if law_target_accel else None,
            accel_limit_m_s2=limit,
        )  # fmt: skip
        a = apn_law(inp, gains).accel_desired_enu_m_s2
        lateral.append(float(a[0]))
        v = v + a * dt
        p = p + v * dt
    return miss, np.array(lateral)


def test_apn_intercepts_a_constant_acceleration_target_as_linear_theory_says():
    limit = available_lateral_accel_m_s2(1 / 3, 45.0, 2.0)  # g
    a_t = 4.0
    miss_apn, cmd_apn = _intercept(True, a_t, limit)
    miss_pn, cmd_pn = _intercept(False, a_t, limit)
    assert miss_apn < 0.05 and miss_pn < 0.05
    # APN (N = 3): N/2 a_T (1 - t/t_f)^(N - 2), within 10 % of its start up to the last 0.1 s;
    # PN's command grows toward the end (to N / (N - 2) a_T in the linear limit) past APN's
    t = np.arange(len(cmd_apn)) * 0.01
    theory = 1.5 * a_t * (1.0 - t / (len(cmd_apn) * 0.01))
    early = t < t[-1] - 0.1
    np.testing.assert_allclose(cmd_apn[early], theory[early], atol=0.1 * 1.5 * a_t)
    assert cmd_apn.max() <= 1.5 * a_t * 1.001
    assert abs(cmd_apn[-20:].mean()) < 0.25 * a_t
    assert cmd_pn.max() > 1.2 * cmd_apn.max()
    assert cmd_pn[:10].max() < 0.5 * a_t
    # a harder target: PN misses by metres, APN still within 0.1 m
    miss_apn, cmd_apn = _intercept(True, 6.0, limit)
    miss_pn, _ = _intercept(False, 6.0, limit)
    assert miss_apn < 0.1 and miss_pn > 1.0
    assert cmd_apn.max() <= limit


def _motion(accel, var, velocity=(0.0, 0.0, 0.0)):
    return MotionEstimate(0.0, accel, velocity, var, (0.5, 0.3, 0.2))


def test_an_acceleration_within_its_noise_is_not_flown():
    # sigma = sqrt(0.75 / 3) = 0.5 m/s^2: |a| = 0.4 is 0.8 sigma (off), 0.75 is 1.5 sigma
    # (half), 3 is 6 sigma (whole); all normal to the target's velocity (0, 3, -4)
    v = (0.0, 3.0, -4.0)
    assert manoeuvre_accel_m_s2(_motion((0.4, 0.0, 0.0), 0.75, v), 1.0, 2.0) == (0.0, 0.0, 0.0)
    half = manoeuvre_accel_m_s2(_motion((0.0, 0.6, 0.45), 0.75, v), 1.0, 2.0)
    np.testing.assert_allclose(half, (0.0, 0.3, 0.225), rtol=1e-12)
    whole = manoeuvre_accel_m_s2(_motion((3.0, 0.0, 0.0), 0.75, v), 1.0, 2.0)
    assert whole == (3.0, 0.0, 0.0)
    assert manoeuvre_accel_m_s2(None, 1.0, 2.0) is None


def test_only_the_acceleration_normal_to_the_targets_velocity_is_flown():
    """A speed change is bounded by the target's speed range (a jink's lasts 0.3 s), a turn's
    normal acceleration is not: the part along the velocity is not flown, and a target at
    rest (under MIN_TURN_SPEED_M_S) has nothing but speed change."""
    # 3 m/s^2 across a target flying 4 m/s east plus 2 m/s^2 along it: the 3 m/s^2 is flown
    a = manoeuvre_accel_m_s2(_motion((2.0, 3.0, 0.0), 0.01, (4.0, 0.0, 0.0)), 1.0, 2.0)
    np.testing.assert_allclose(a, (0.0, 3.0, 0.0), atol=1e-12)
    along = manoeuvre_accel_m_s2(_motion((0.0, 0.0, -5.0), 0.01, (0.0, 0.0, -2.0)), 1.0, 2.0)
    np.testing.assert_allclose(along, (0.0, 0.0, 0.0), atol=1e-12)
    # darting from rest: 8 m/s^2 at 0.4 m/s and at 2.4 m/s along its own velocity
    assert MIN_TURN_SPEED_M_S == 0.5
    rest = manoeuvre_accel_m_s2(_motion((0.0, 8.0, 0.0), 0.01, (0.3, 0.0, 0.0)), 1.0, 2.0)
    assert rest == (0.0, 0.0, 0.0)
    dart = manoeuvre_accel_m_s2(_motion((0.0, 8.0, 0.0), 0.01, (0.0, 2.4, 0.0)), 1.0, 2.0)
    np.testing.assert_allclose(dart, (0.0, 0.0, 0.0), atol=1e-12)


def test_time_to_go_is_range_over_closing_speed():
    n = (0.0, 1.0, 0.0)
    v = np.array((0.0, 10.0, 0.0))
    assert time_to_go_s(20.0, n, v, None) == pytest.approx(2.0)
    # a target receding at 2 m/s along the LOS: closing at 8
    rec = _motion((0.0, 0.0, 0.0), 0.0, velocity=(1.0, 2.0, 0.0))
    assert time_to_go_s(20.0, n, v, rec) == pytest.approx(2.5)
    assert math.isnan(time_to_go_s(None, n, v, None))
    assert math.isnan(time_to_go_s(20.0, n, -v, None))  # opening


def test_the_endgame_flies_the_endgame_limit():
    """A target accelerating hard across the LOS: the command saturates at the tilt limit
    (g at 45 deg) until the time to go falls under t_end, then at the endgame's (70 deg:
    g tan 70 = 26.95 m/s^2, just under the thrust's 26.96 with 2 m/s^2 kept for the
    vertical)."""
    gains = Gains()
    lim = available_lateral_accel_m_s2(1 / 3, gains.tilt_max, gains.a_z_margin)
    end = available_lateral_accel_m_s2(1 / 3, gains.tilt_end, gains.a_z_margin)
    assert end == pytest.approx(G * math.tan(math.radians(70.0)), rel=1e-12)  # 26.95
    n = np.array((0.0, 1.0, 0.0))
    norms = []
    for t_go in (2.0 * gains.t_end, 0.5 * gains.t_end, math.nan):
        inp = GuidanceInput(
            0.01, n, 0.0, 0.0, 0.0, 0.0, np.array((0.0, 10.0, 0.0)), (0.0, 0.0), np.eye(3),
            target_accel_enu_m_s2=(30.0, 0.0, 0.0), accel_limit_m_s2=lim,
            time_to_go_s=t_go, endgame_accel_limit_m_s2=end,
        )  # fmt: skip
        norms.append(float(np.linalg.norm(apn_law(inp, gains).accel_desired_enu_m_s2)))
    assert norms[0] == pytest.approx(lim, rel=1e-9)
    assert norms[1] == pytest.approx(end, rel=1e-9)
    assert norms[2] == pytest.approx(lim, rel=1e-9)  # unknown time to go: no endgame


def _circling(speed_m_s: float, accel_m_s2: float, t_s: float):
    """A target at the origin flying north at ``speed_m_s`` and turning left at ``accel_m_s2``
    (omega = a / v): its velocity and acceleration now and its position ``t_s`` later."""
    w = accel_m_s2 / speed_m_s
    R = speed_m_s / w
    v, a = np.array((0.0, speed_m_s, 0.0)), np.array((-accel_m_s2, 0.0, 0.0))
    later = np.array((R * (math.cos(w * t_s) - 1.0), R * math.sin(w * t_s), 0.0))
    return v, a, w, later


@pytest.mark.parametrize("accel", [5.0, 7.5])
@pytest.mark.parametrize("t_go", [0.5, 1.0, 1.5])
def test_the_turn_prediction_nulls_a_coordinated_turns_zero_effort_miss(accel, t_go):
    """An interceptor aiming at where the law predicts the target at t_go, with the target 5 m/s
    in a coordinated turn: the turn's prediction (t^2 / 2 a_eq beyond v t) is where the target
    is, so the law's term N/2 a_eq,perp is N / t^2 times the turn's zero-effort miss across
    the LOS; the constant-acceleration prediction leaves R (wt - sin wt) along the target's
    velocity (0.83 m at 5 m/s^2 and 1 s, 1.66 m at 7.5), several hit radii."""
    v, a, w, later = _circling(5.0, accel, t_go)
    a_eq = np.array(turn_prediction_accel_m_s2(tuple(a), w, t_go, 1.5))
    ct_miss = float(np.linalg.norm(v * t_go + 0.5 * t_go**2 * a_eq - later))
    ca_miss = float(np.linalg.norm(v * t_go + 0.5 * t_go**2 * a - later))
    behind = 5.0**2 / accel * (w * t_go - math.sin(w * t_go))  # R (wt - sin wt)
    assert ct_miss < 1e-9
    assert ca_miss >= behind > 0.06  # the along-track part alone
    if t_go == 1.0:
        assert ca_miss > {5.0: 0.8, 7.5: 1.6}[accel] > 0.3  # the hit radius
    # the term flown: N / t^2 times the turn's miss across the LOS (east here)
    los = (1.0, 0.0, 0.0)
    zem = later - v * t_go
    zem_perp = zem - (zem @ np.array(los)) * np.array(los)
    np.testing.assert_allclose(apn_term(tuple(a_eq), los, 3.0), 3.0 / t_go**2 * zem_perp, atol=1e-9)


def test_the_turn_prediction_without_a_turn_is_the_constant_acceleration_term():
    """omega -> 0, t_go -> 0, no t_go or no horizon (t_turn 0, the default): the prediction is
    a (APN's N/2 a); beyond the horizon it predicts over the horizon, and the vertical part
    stays as it is."""
    a = (1.0, -2.0, 0.5)
    for w in (1e-9, 1e-6, 1e-4):
        np.testing.assert_allclose(turn_prediction_accel_m_s2(a, w, 1.0, 1.5), a, atol=w + 1e-12)
    assert turn_prediction_accel_m_s2(a, 0.0, 1.0, 1.5) == a
    assert turn_prediction_accel_m_s2(a, 1.0, math.nan, 1.5) == a
    assert turn_prediction_accel_m_s2(a, 1.0, -1.0, 1.5) == a  # not closing
    assert turn_prediction_accel_m_s2(a, 1.0, 1.0, 0.0) == a  # no horizon: off
    np.testing.assert_allclose(turn_prediction_accel_m_s2(a, 1.0, 1e-7, 1.5), a, atol=1e-6)
    capped = turn_prediction_accel_m_s2(a, 1.2, 1.5, 1.5)
    assert turn_prediction_accel_m_s2(a, 1.2, 10.0, 1.5) == capped
    assert capped[2] == 0.5
    # both sides of the small-angle series agree (the branch at wt = 1e-4)
    below = turn_prediction_accel_m_s2(a, 0.99e-4, 1.0, 1.5)
    above = turn_prediction_accel_m_s2(a, 1.01e-4, 1.0, 1.5)
    np.testing.assert_allclose(below, above, atol=1e-5)


def test_the_law_flies_the_turn_prediction_with_its_turn_rate_and_time_to_go():
    """apn_law with the target's turn rate, a time to go and t_turn: the command differs from
    the one without a turn rate by exactly N/2 (a_eq - a) across the LOS (below the limit);
    with t_turn 0 (the default) the turn rate changes nothing."""
    gains = Gains().replace(t_turn=1.5)
    n = np.array((0.0, 1.0, 0.0))
    a_t = (-2.0, 0.0, 0.0)  # across the LOS (north): a target flying north turning left

    def command(turn_rate: float, gains: Gains = gains) -> np.ndarray:
        inp = GuidanceInput(
            0.01, n, 0.0, 0.0, 0.0, 0.0, np.array((0.0, 10.0, 0.0)), (0.0, 0.0), np.eye(3),
            target_accel_enu_m_s2=a_t, accel_limit_m_s2=20.0, time_to_go_s=1.0,
            target_turn_rate_rad_s=turn_rate,
        )  # fmt: skip
        return apn_law(inp, gains).accel_desired_enu_m_s2

    n_gain = 0.5 * (gains.K_y + gains.K_z)  # N
    a_eq = np.array(turn_prediction_accel_m_s2(a_t, 0.8, 1.0, 1.5))
    expected = 0.5 * n_gain * (a_eq - np.array(a_t)) * np.array((1.0, 0.0, 1.0))
    np.testing.assert_allclose(command(0.8) - command(0.0), expected, atol=1e-9)
    assert abs(expected[0]) > 0.1
    assert np.array_equal(command(0.8, Gains()), command(0.0, Gains()))


def test_the_turns_speed_cap_matches_the_vehicles_tightest_turn_to_the_targets():
    """A target at 5 m/s turning at 7.5 m/s^2 (1.5 rad/s, radius 3.33 m) and a limit of
    9.81 m/s^2: the vehicle turns on that radius at sqrt(9.81 x 3.33) = 5.72 m/s; k scales
    it; no turn, no k or a target at rest: no cap."""
    a = (0.0, 7.5, 0.0)
    cap = turn_speed_cap_m_s(a, 1.5, G, 1.0)
    assert cap == pytest.approx(math.sqrt(G * 25.0 / 7.5), rel=1e-12)  # 5.72 m/s
    assert cap**2 / G == pytest.approx(25.0 / 7.5, rel=1e-12)  # the target's radius
    assert turn_speed_cap_m_s(a, -1.5, G, 0.5) == pytest.approx(0.5 * cap, rel=1e-12)
    assert turn_speed_cap_m_s(a, 1.5, G, 0.0) == math.inf
    assert turn_speed_cap_m_s(None, 1.5, G, 1.0) == math.inf
    assert turn_speed_cap_m_s((0.0, 0.3, 0.0), 1.5, G, 1.0) == math.inf  # no turn to match
    assert turn_speed_cap_m_s(a, 0.01, G, 1.0) == math.inf
    assert turn_speed_cap_m_s((0.0, 0.6, 0.0), 3.0, G, 1.0) == math.inf  # 0.2 m/s: at rest


def test_the_law_flies_no_faster_than_the_turns_speed_cap():
    """The speed ramp's reference is capped: flying at 9 m/s toward a turning target, the
    capped law decelerates along the LOS where the default one accelerates."""
    n = np.array((0.0, 1.0, 0.0))

    def along(gains: Gains) -> float:
        inp = GuidanceInput(
            0.01, n, 0.0, 0.0, 0.0, 0.0, np.array((0.0, 9.0, 0.0)), (0.0, 0.0), np.eye(3),
            target_accel_enu_m_s2=(7.5, 0.0, 0.0), accel_limit_m_s2=G,
            target_turn_rate_rad_s=1.5, time_to_go_s=3.0,
        )  # fmt: skip
        return float(apn_law(inp, gains).accel_desired_enu_m_s2 @ n)

    assert along(Gains()) > 0.0
    assert along(Gains().replace(k_turn_v=1.0)) < 0.0


def test_the_endgame_caps_the_approach_speed_within_its_range():
    """Within r_end (20 m) of the target the speed ramp's cap is v_end (4 m/s) over the
    target's speed (0 when unknown); farther, with the range unknown (nan) or v_end 0 (off)
    there is none."""
    gains = Gains()
    assert (gains.v_end, gains.r_end) == (4.0, 20.0)
    assert endgame_speed_cap_m_s(19.9, 0.0, gains) == 4.0
    assert endgame_speed_cap_m_s(5.0, 4.5, gains) == 8.5
    assert endgame_speed_cap_m_s(5.0, math.nan, gains) == 4.0
    assert endgame_speed_cap_m_s(0.5, 1.0, gains.replace(v_end=2.0)) == 3.0
    for range_m, g in (
        (20.0, gains),
        (30.0, gains),
        (math.nan, gains),
        (5.0, gains.replace(v_end=0.0)),
    ):
        assert endgame_speed_cap_m_s(range_m, 0.0, g) == math.inf


def test_the_law_closes_in_no_faster_than_v_end():
    """Flying at 7 m/s toward a hovering target 8 m away the law decelerates along the LOS (the
    speed ramp's reference is v_end, 4 m/s); toward one flying at 5 m/s (reference 9 m/s), 30 m
    away, or with v_end 0, it accelerates."""
    n = np.array((0.0, 1.0, 0.0))

    def along(gains: Gains, range_m: float, target_speed_m_s: float = 0.0) -> float:
        inp = GuidanceInput(
            0.01, n, 0.0, 0.0, 0.0, 0.0, np.array((0.0, 7.0, 0.0)), (0.0, 0.0), np.eye(3),
            target_accel_enu_m_s2=(0.0, 0.0, 0.0), accel_limit_m_s2=G,
            time_to_go_s=range_m / 7.0, range_est_m=range_m, target_speed_m_s=target_speed_m_s,
        )  # fmt: skip
        return float(apn_law(inp, gains).accel_desired_enu_m_s2 @ n)

    assert along(Gains(), 8.0) < 0.0
    assert along(Gains(), 8.0, 5.0) > 0.0
    assert along(Gains(), 30.0) > 0.0
    assert along(Gains().replace(v_end=0.0), 8.0) > 0.0
    assert along(Gains().replace(v_end=10.0), 8.0) > 0.0
