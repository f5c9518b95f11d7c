"""Ground clearance near a low target (onboard/control/clearance.py): the approach's speed
limit, the held target height and the recovery, against closed-form kinematics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from onboard.control.clearance import (
    CAP_FLOOR_M_S,
    CAP_FRACTION,
    approach_speed_cap_m_s,
    brake_accel,
    clearance_guard_accel,
    held_height_low_m,
    range_interval_m,
    stoppable_descent_m_s,
    target_height_low_m,
    track_speed_cap_m_s,
    upward_accel_m_s2,
)
from onboard.datatypes import GRAVITY_M_S2
from onboard.gains import Gains

G = Gains()


def test_upward_capability_is_the_believed_airframes():
    # thrust-to-weight 3: 2 g upward at full thrust, k_up of it
    assert upward_accel_m_s2(1.0 / 3.0, 0.5) == pytest.approx(GRAVITY_M_S2, rel=1e-12)
    assert upward_accel_m_s2(0.5, 1.0) == pytest.approx(GRAVITY_M_S2, rel=1e-12)
    with pytest.raises(ValueError, match="hover thrust"):
        upward_accel_m_s2(0.0, 0.5)


@settings(max_examples=200, deadline=None)
@given(
    h=st.floats(0.01, 50.0),
    a=st.floats(0.5, 30.0),
    lag=st.floats(0.0, 1.0),
)
def test_stoppable_descent_stops_exactly_within_the_height(h, a, lag):
    """Descending at v, held for the lag, then decelerating at a: the drop is the height."""
    v = stoppable_descent_m_s(h, a, lag)
    assert v > 0.0
    drop = v * lag + v * v / (2.0 * a)
    assert drop == pytest.approx(h, rel=1e-9, abs=1e-12)


def test_no_height_no_descent():
    assert stoppable_descent_m_s(0.0, 10.0, 0.2) == 0.0
    assert stoppable_descent_m_s(-1.0, 10.0, 0.2) == 0.0


def test_range_interval_brackets_the_mean_and_opens_when_unsure():
    lo, hi = range_interval_m(20.0, (0.0, 0.0), (0.1 / 20.0) ** 2)  # 10 % sigma on 1/range
    # 2 sigma: 1/range within (1 +- 0.2) / 20
    assert lo == pytest.approx(20.0 / 1.2, rel=1e-12)
    assert hi == pytest.approx(20.0 / 0.8, rel=1e-12)
    lo, hi = range_interval_m(20.0, (0.0, 0.0), (0.6 / 20.0) ** 2)
    assert hi == math.inf and lo == pytest.approx(20.0 / 2.2, rel=1e-12)
    assert range_interval_m(math.nan, (0.0, 0.0), 1e-4) == (0.0, math.inf)


def test_target_height_takes_the_range_that_puts_it_lowest():
    # LOS 30 deg down: the far end of the range interval is the lower target
    assert target_height_low_m(10.0, -0.5, 10.0, 16.0) == pytest.approx(2.0, abs=1e-12)
    # LOS up: the near end
    assert target_height_low_m(2.0, 0.5, 10.0, 16.0) == pytest.approx(7.0, abs=1e-12)
    assert target_height_low_m(10.0, -0.5, 10.0, math.inf) == -math.inf


def test_held_height_decays_at_the_sink_rate_and_rises_to_a_better_bound():
    assert held_height_low_m(3.0, 0.5, 1.0, 1.0) == pytest.approx(2.5, abs=1e-12)
    assert held_height_low_m(3.0, 0.5, 2.8, 1.0) == pytest.approx(2.8, abs=1e-12)
    assert held_height_low_m(-math.inf, 0.01, 1.5, 1.0) == 1.5


def test_the_cap_leaves_room_to_stop_above_h_clear():
    """At the target (no range left to shed) the cap's descent rate is CAP_FRACTION of the
    one that stops above h_clear."""
    a_up = upward_accel_m_s2(1.0 / 3.0, G.k_up)
    h_t = 1.5
    s = math.sin(math.radians(40.0))
    los = -s
    v = (0.0, 5.0 * math.cos(math.radians(40.0)), -5.0 * s)
    cap = approach_speed_cap_m_s(h_t, los, v, 0.0, a_up, G)
    v_down = CAP_FRACTION * stoppable_descent_m_s(h_t - G.h_clear, a_up, G.t_up_lag)
    assert cap * s == pytest.approx(v_down, rel=1e-9)
    # stopping from that descent (lag, then a_up) leaves more than h_clear under the target
    drop = cap * s * G.t_up_lag + (cap * s) ** 2 / (2.0 * a_up)
    assert h_t - drop > G.h_clear
    # farther out the ramp may be faster: it can still shed k_a / 2 over the range
    far = approach_speed_cap_m_s(h_t, los, v, 10.0, a_up, G)
    assert far == pytest.approx(math.sqrt(cap * cap + G.k_a * 10.0), rel=1e-9)


def test_the_cap_leaves_high_targets_and_level_paths_alone():
    a_up = upward_accel_m_s2(1.0 / 3.0, G.k_up)
    dive = (0.0, 7.0, -7.0)
    assert approach_speed_cap_m_s(12.0, -0.7, dive, 0.0, a_up, G) == G.v_max
    assert approach_speed_cap_m_s(1.0, 0.0, (0.0, 10.0, 0.0), 0.0, a_up, G) == G.v_max
    # a target at or under h_clear: the floor (the law keeps flying, slowly)
    assert approach_speed_cap_m_s(0.2, -0.7, dive, 0.0, a_up, G) == CAP_FLOOR_M_S


def test_track_cap_without_a_range_holds_the_last_bound():
    a_up = upward_accel_m_s2(1.0 / 3.0, G.k_up)
    los = (0.0, 0.8, -0.6)
    vel = (0.0, 6.0, -4.5)
    P = np.zeros((6, 6))
    P[2, 2] = (0.05 / 10.0) ** 2
    depth = (10.0, None, P)
    cap1, low1 = track_speed_cap_m_s(-math.inf, 0.01, 8.0, los, vel, (0.0, 0.0), depth, a_up, G)
    _lo, hi = range_interval_m(10.0, (0.0, 0.0), P[2, 2])
    assert low1 == pytest.approx(8.0 - 0.6 * hi, abs=1e-12)
    cap2, low2 = track_speed_cap_m_s(low1, 0.5, 7.0, los, vel, (0.0, 0.0), None, a_up, G)
    assert low2 == pytest.approx(low1 - 0.5 * G.v_tgt_sink, abs=1e-12)
    assert cap2 < cap1  # lower bound, shorter range: slower


def test_guard_brakes_only_below_the_braking_curve():
    a_up = upward_accel_m_s2(1.0 / 3.0, G.k_up)
    a = np.array((1.0, 2.0, -3.0))
    h = 2.0
    v_ok = stoppable_descent_m_s(h - G.h_clear, a_up, G.t_up_lag)
    same = clearance_guard_accel(a, h, -0.99 * v_ok, a_up, G)
    assert same is a
    out = clearance_guard_accel(a, h, -1.01 * v_ok, a_up, G)
    np.testing.assert_allclose(out, (1.0, 2.0, a_up), rtol=0, atol=0)
    # under h_clear any descent is stopped
    np.testing.assert_allclose(clearance_guard_accel(a, 0.3, -0.1, a_up, G)[2], a_up)


def test_brake_after_the_pass_uses_the_upward_capability():
    a_up = upward_accel_m_s2(1.0 / 3.0, G.k_up)
    v = np.array((0.0, 6.0, -6.0))
    out = brake_accel(v, G, a_up)
    assert out[2] == pytest.approx(min(G.k_brake_z * 6.0, a_up), abs=1e-12)
    assert out[2] > G.a_max
    # the horizontal waits until the vertical is within a_max
    assert out[0] == 0.0 and out[1] == 0.0
    np.testing.assert_allclose(brake_accel(v, G)[2], G.a_max)  # without: a_max as before


def test_k_up_zero_switches_both_parts_off():
    a = np.array((1.0, 2.0, -3.0))
    assert clearance_guard_accel(a, 0.1, -5.0, upward_accel_m_s2(0.3, 0.0), G) is a
    cap, low = track_speed_cap_m_s(2.0, 0.01, 3.0, (0.0, 0.6, -0.8), (0.0, 3.0, -4.0),
                                   (0.0, 0.0), None, 0.0, G)  # fmt: skip
    assert cap == math.inf and low == 2.0


def _low_static_sortie(gains: Gains, keep_records: bool = False):
    """A balloon 1.4 m above the ground 25 m ahead and 40 deg down-range of a vehicle at 10 m
    (the static campaign's target 12 at seed 0), realistic defaults (outdoor-gnss)."""
    import dataclasses

    from groundstation.scenario import load_scenario, with_changes
    from groundstation.sim.simulation import Simulation

    base = load_scenario("static-ahead-20m")
    target = dataclasses.replace(base.target, position_m=(10.9, 22.7, 1.43))
    sc = with_changes(base, name="static-low", target=target)
    sim = Simulation(sc, "png", 12, gains=gains, keep_records=keep_records)
    return sim.run(), sim.records


def test_a_low_target_is_hit_and_the_vehicle_recovers_above_the_ground():
    """Without the limit (k_up = 0) the vehicle passes the target at over 10 m/s, diving at
    over 6 m/s, and hits the ground; with it the approach slows to about 2 m/s, hits, and the
    recovery stops the descent above h_clear (1 m; the target is at 1.43 m)."""
    off, _ = _low_static_sortie(Gains(k_up=0.0))
    assert off.outcome == "CRASHED" and off.miss_m < off.hit_radius_m
    on, frames = _low_static_sortie(Gains(), keep_records=True)
    assert on.outcome == "HIT" and on.recovered
    assert on.miss_m < 0.1
    assert 1.5 < on.terminal_speed_m_s < 3.0
    assert off.terminal_speed_m_s > 10.0
    assert on.min_alt_after_pass_m > 1.0
    # the operator sees the limit: on the control message, on the link (NaN: none)
    from onboard.link.telemetry import loop_values

    caps = [f.telemetry.speed_cap_m_s for f in frames if f.time_s < on.intercept_time_s]
    assert min(caps) == CAP_FLOOR_M_S and max(caps) == math.inf  # none before the track
    slow = next(f.telemetry for f in frames if f.telemetry.speed_cap_m_s < 3.0)
    assert loop_values(slow)["speed_cap_m_s"] == slow.speed_cap_m_s
    assert math.isnan(loop_values(frames[0].telemetry)["speed_cap_m_s"])
