"""The control maths against hand-worked cases of the paper's equations (DESIGN.md §3)."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from onboard.camera_model import CameraModel
from onboard.control import guidance_reference
from onboard.control.attitude import attitude_command, desired_thrust_direction
from onboard.control.fov_hold import yaw_rate_command
from onboard.control.guidance import (
    GuidanceInput,
    believed_drag_floats,
    direction_angles,
    direction_from_angles,
    line_of_sight,
    los_change,
    png_law,
    pursuit_law,
    ramped_speed,
    saturate_norm,
)
from onboard.datatypes import VehicleParams
from onboard.gains import Gains

G = Gains()
CAM = CameraModel()


def _inp(v, dq_y=0.0, dq_z=0.0, los=(0.0, 1.0, 0.0), dt=0.01):
    n = np.asarray(los, float)
    n = n / np.linalg.norm(n)
    q_y, q_z = direction_angles(n)
    return GuidanceInput(dt, n, q_y, q_z, dq_y, dq_z, np.asarray(v, float), (0.0, 0.0), np.eye(3))


# --- eq. 5: line of sight -----------------------------------------------------------------
def test_los_centre_right_and_up(R_north):
    R_WC = R_north @ CAM.R_BC
    assert_allclose(line_of_sight(0.0, 0.0, R_WC), [0, 1, 0], atol=1e-12)
    # e = (f, 0): 45 deg right of the nose, facing north -> north-east
    s = math.sqrt(0.5)
    assert_allclose(line_of_sight(1.0, 0.0, R_WC), [s, s, 0], atol=1e-12)
    # e = (0, -f): 45 deg above (image v grows downward)
    assert_allclose(line_of_sight(0.0, -1.0, R_WC), [0, s, s], atol=1e-12)


# --- eqs. 6-7: angles with atan2 ----------------------------------------------------------
def test_angles_elevation_azimuth():
    assert_allclose(direction_angles(np.array([0.0, 1.0, 0.0])), (0.0, 0.0))
    assert_allclose(direction_angles(np.array([1.0, 0.0, 0.0])), (0.0, math.pi / 2))
    el, az = direction_angles(np.array([0.0, -1.0, 1.0]) / math.sqrt(2))
    assert_allclose((el, az), (math.pi / 4, math.pi))  # behind: atan2 keeps the quadrant
    for el, az in ((0.3, -2.5), (-0.7, 3.0), (1.2, 0.1)):
        assert_allclose(direction_angles(direction_from_angles(el, az)), (el, az), atol=1e-12)


def test_azimuth_change_wraps_across_180_deg():
    a = direction_angles(np.array([-0.01, -1.0, 0.0]))[1]  # just west of south: ~ -179.4 deg
    b = direction_angles(np.array([0.01, -1.0, 0.0]))[1]  # just east of south: ~ +179.4 deg
    assert a < -3.1 and b > 3.1
    # from just east of south (b) to just west of south (a): azimuth (clockwise from north)
    # grows by 2 * atan(0.01) = 0.019999 rad, not by -2 pi
    dq_y, dq_z = los_change(0.0, a, 0.0, b)
    assert_allclose(dq_z, 2 * math.atan(0.01), atol=1e-12)
    assert dq_y == 0.0


# --- eqs. 8-9, 14, 17: PNG -----------------------------------------------------------------
def test_png_rising_los_pitches_velocity_up():
    """v = (0, 5, 0), dq_y = 0.01 rad, K_y = 3, k_a = 2, dt = 0.01 (worked by hand):
    sigma_yd = 0.03; |v_d| = 5.02; v_d = (0, 5.017741, 0.150577);
    a = (v_d - v)/dt = (0, 1.774117, 15.057741); |a| = 15.1619 > a_max = 5
    -> a_d = (0, 0.585058, 4.965653)."""
    out = png_law(_inp([0, 5, 0], dq_y=0.01), G)
    assert_allclose(out.accel_desired_enu_m_s2, [0.0, 0.585058, 4.965653], atol=1e-5)
    assert out.accel_desired_enu_m_s2[2] > 0  # velocity pitched up toward the target
    assert not out.hovering


def test_png_los_turning_right_turns_velocity_right():
    out = png_law(_inp([0, 5, 0], dq_z=0.001), Gains(a_max=30))
    # sigma_zd = 0.003 -> v_d = 5.02 (sin .003, cos .003, 0); a_x = 5.02 sin(.003)/0.01
    assert_allclose(out.accel_desired_enu_m_s2[0], 5.02 * math.sin(0.003) / 0.01, rtol=1e-9)
    assert out.accel_desired_enu_m_s2[0] > 0  # toward +x = right of a northbound vehicle


def test_png_no_los_change_is_pure_speed_ramp():
    out = png_law(_inp([0, 5, 0]), G)
    assert_allclose(out.accel_desired_enu_m_s2, [0, G.k_a, 0], atol=1e-9)
    assert_allclose((out.vel_elev_rad, out.vel_azim_rad), (0.0, 0.0))
    # k_a net of drag: the believed drag and disturbance's along-track part is overcome on top
    # (its part across the velocity is the attitude loop's), a tailwind never brakes
    inp = _inp([0, 5, 0])
    inp.disturbance_enu_m_s2 = (0.4, -0.5, 0.0)
    out = png_law(inp, G)
    assert_allclose(out.accel_desired_enu_m_s2, [0, G.k_a + 0.5, 0], atol=1e-9)
    inp.disturbance_enu_m_s2 = (0.0, 0.5, 0.0)
    assert_allclose(png_law(inp, G).accel_desired_enu_m_s2, [0, G.k_a, 0], atol=1e-9)


def test_believed_drag_is_the_rotor_plane_model_plus_the_observers_estimate():
    """Level (thrust axis up) at 10 m/s north: -k_drag v; climbing straight up: no rotor-plane
    velocity, only d^; d^ adds."""
    k = G.k_drag
    assert_allclose(believed_drag_floats(0, 10, 0, 0, 0, 1, 0, 0, 0, k), (0, -10 * k, 0))
    assert_allclose(believed_drag_floats(0, 0, 5, 0, 0, 1, 0.1, 0.2, 0.3, k), (0.1, 0.2, 0.3))
    s = math.sqrt(0.5)  # thrust axis tilted 45 deg forward: half the speed in the plane
    got = believed_drag_floats(0, 10, 0, 0, s, s, 0, 0, 0, k)
    assert_allclose(got, (0, -5 * k, 5 * k), atol=1e-12)


def test_hover_case_accelerates_along_los():
    los = np.array([0.0, 3.0, 4.0]) / 5.0
    out = png_law(_inp([0.1, 0.2, 0.0], dq_y=0.05, los=los), G)
    assert out.hovering
    assert_allclose(out.accel_desired_enu_m_s2, G.k_a * los, atol=1e-12)
    assert math.isnan(out.vel_elev_rad)


@pytest.mark.parametrize("v", [[0.0, -3.0, 0.0], [2.0, -0.5, 0.0], [0.3, -6.0, -1.0]])
def test_moving_away_from_the_target_accelerates_along_los(v):
    """Flying away from the target (v . n_t < 0) PN has no LOS rate to turn on and the speed
    ramp would push along the velocity: the law flies the LOS, as from the hover."""
    los = np.array([0.0, 1.0, -0.2]) / math.hypot(1.0, 0.2)
    out = png_law(_inp(v, dq_y=0.01, dq_z=-0.02, los=los), G)
    assert out.hovering and math.isnan(out.vel_azim_rad)
    assert_allclose(out.accel_desired_enu_m_s2, G.k_a * los, atol=1e-12)
    ref = guidance_reference.png(
        0.01, los, math.asin(los[2]), (0.01, -0.02), np.asarray(v, float), np.eye(3)[:, 2],
        (math.inf, -math.inf), 20.0, None, 0.0, G,
    )  # fmt: skip
    assert ref[3] and ref[0] @ los > 0.0
    # closing at any angle under 90 degrees PN flies (the velocity angles are defined)
    assert not png_law(_inp([3.0, 0.1, 0.0], los=los), G).hovering


def test_speed_ramp_and_cap():
    # far below v_max: the full k_a (eq. 14)
    assert_allclose(ramped_speed(5.0, G, 0.01), 5.02)
    # within k_a / k_brake of v_max: a speed hold, k_brake (v_max - |v|)
    assert_allclose(ramped_speed(11.5, G, 0.01), 11.5 + 0.5 * 0.01)
    assert ramped_speed(12.0, G, 0.01) == 12.0
    # faster than v_max: slow down, at most at k_a, never by the whole excess at once
    assert_allclose(ramped_speed(12.5, G, 0.01), 12.5 - 0.5 * 0.01)
    assert_allclose(ramped_speed(15.0, G, 0.01), 15.0 - 2.0 * 0.01)


def test_png_at_the_speed_cap_keeps_tangential_acceleration_within_k_a():
    for speed in (11.99, 12.0, 12.03, 13.0):
        out = png_law(_inp([0, speed, 0]), G)
        assert abs(out.accel_desired_enu_m_s2[1]) <= G.k_a + 1e-9, speed


def test_acceleration_saturation_keeps_direction():
    a = saturate_norm(np.array([30.0, 40.0, 0.0]), 5.0)
    assert_allclose(a, [3.0, 4.0, 0.0])
    assert_allclose(saturate_norm(np.array([1.0, 0.0, 0.0]), 5.0), [1, 0, 0])


def test_pursuit_points_velocity_along_los():
    los = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)
    out = pursuit_law(_inp([0, 5, 0], los=los), Gains(a_max=30))
    a = out.accel_desired_enu_m_s2
    assert a[0] > 0 and a[1] < 0  # turn right, shedding the wrong-way component


def test_png_against_zero_effort_miss_solution():
    """Planar PN with ideal dynamics against the textbook heading-error solution:
    a_n(t) = N V eps / t_f (1 - t / t_f)^(N - 2); for N = 3 a linear decay to zero."""
    gains = Gains(k_a=0.0, a_max=30.0)
    V, eps, R0, dt = 10.0, 0.05, 100.0, 0.001
    N = gains.K_z
    p = np.zeros(3)
    v = V * np.array([math.sin(eps), math.cos(eps), 0.0])
    target = np.array([0.0, R0, 0.0])
    t_f = R0 / V
    q_prev = None
    samples = {}
    t = 0.0
    miss = math.inf
    while t < 1.2 * t_f:
        rel = target - p
        rng = np.linalg.norm(rel)
        miss = min(miss, rng)
        if rel @ v < 0:
            break
        q = direction_angles(rel / rng)
        dq = (0.0, 0.0) if q_prev is None else los_change(*q, *q_prev)
        q_prev = q
        out = png_law(GuidanceInput(dt, rel / rng, *q, *dq, v, (0, 0), np.eye(3)), gains)
        a = out.accel_desired_enu_m_s2
        for frac in (0.25, 0.5, 0.75):
            if frac not in samples and t >= frac * t_f:
                a_n = a - (a @ v) / (v @ v) * v
                samples[frac] = np.linalg.norm(a_n)
        v = v + a * dt
        p = p + v * dt
        t += dt
    assert miss < 0.02
    for frac, a_n in samples.items():
        expected = N * V * eps / t_f * (1 - frac) ** (N - 2)
        assert_allclose(a_n, expected, rtol=0.06, err_msg=f"at t = {frac} t_f")


# --- eq. 13: FOV-holding yaw -----------------------------------------------------------------
def test_target_right_of_centre_yaws_clockwise():
    assert_allclose(yaw_rate_command(100.0, 0.0, G), -3.0)  # -k_p e_x = -0.03 * 100
    assert yaw_rate_command(-50.0, 0.0, G) > 0
    # moving right at 100 px/s adds -k_d * 100 = -1 rad/s
    assert_allclose(yaw_rate_command(0.0, 100.0, G), -1.0)


# --- eqs. 18-24: attitude loop ---------------------------------------------------------------
VEH = VehicleParams(mass_kg=1.5, max_thrust_n=3 * 1.5 * 9.81)


def test_hover_gives_zero_rates_and_hover_thrust(R_north):
    w, thrust = attitude_command(np.zeros(3), R_north, 0.0, G, VEH)
    assert_allclose(w, 0.0, atol=1e-12)
    assert_allclose(thrust, 1.0 / 3.0)


def test_forward_acceleration_pitches_nose_down(R_north):
    """a_d = (0, 2, 0) facing north: tilt phi = atan(2 / 9.81) = 0.20134 rad about body +y
    (nose down in FLU); w_1 = k_R sin(phi) = 8 * 0.19979 = 1.59811 rad/s."""
    w, thrust = attitude_command(np.array([0.0, 2.0, 0.0]), R_north, 0.0, G, VEH)
    assert_allclose(w, [0.0, 1.598115, 0.0], atol=1e-6)
    assert_allclose(thrust, 1.0 / 3.0, atol=1e-12)  # n_f still vertical: m g / T_max


def test_rightward_acceleration_rolls_right(R_north):
    w, _ = attitude_command(np.array([2.0, 0.0, 0.0]), R_north, 0.0, G, VEH)
    assert w[0] > 1.5 and abs(w[1]) < 1e-9  # roll right is positive about body x (FLU)


def test_yaw_rate_passes_through_and_tilt_has_no_yaw(R_north):
    w, _ = attitude_command(np.array([1.0, 2.0, 0.5]), R_north, 0.0, G, VEH)
    assert abs(w[2]) < 1e-12
    w, _ = attitude_command(np.zeros(3), R_north, -0.7, G, VEH)
    assert_allclose(w, [0, 0, -0.7], atol=1e-12)


def test_rate_saturation_scales_whole_vector(R_north):
    w, _ = attitude_command(np.array([20.0, 0.0, 0.0]), R_north, 2.0, G, VEH)
    assert_allclose(np.linalg.norm(w), G.omega_max)
    unsat, _ = attitude_command(np.array([20.0, 0.0, 0.0]), R_north, 2.0, Gains(omega_max=10), VEH)
    assert_allclose(w / np.linalg.norm(w), unsat / np.linalg.norm(unsat), atol=1e-9)


@pytest.mark.parametrize(("a_z", "expected"), [(-20.0, 0.0), (50.0, 1.0), (9.81, 2 / 3)])
def test_thrust_clipped_to_range(R_north, a_z, expected):
    _, thrust = attitude_command(np.array([0.0, 0.0, a_z]), R_north, 0.0, G, VEH)
    assert_allclose(thrust, expected, atol=1e-9)


def test_free_fall_request_points_thrust_up():
    assert_allclose(desired_thrust_direction(np.array([0.0, 0.0, -9.81])), [0, 0, 1])
