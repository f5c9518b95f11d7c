"""The value checks of a parsed scenario (ranges, consistency between sections, physics):
every problem is recorded, none stops the others from being checked."""

from __future__ import annotations

import math

from onboard.constants import GRAVITY_M_S2
from onboard.gains import GainError, Gains

from .physics import helium_gross_lift_n, jet_reference_problem
from .problems import Problems
from .specs import ESTIMATE_PROFILES, MOTIONS, WIND_MODELS, Scenario


def validate(s: Scenario, problems: Problems) -> None:
    """Record in ``problems`` every value of ``s`` out of range or inconsistent."""
    t, c, i, sim = s.target, s.camera, s.interceptor, s.sim
    check = problems.check
    check(s.duration_s > 0, "duration_s", "must be positive")
    check(t.motion in MOTIONS, "target.motion", f"must be one of {', '.join(MOTIONS)}")
    check(t.diameter_m > 0, "target.diameter_m", "must be positive")
    if t.motion == "sinusoid":
        check(t.period_s > 0, "target.period_s", "sinusoid needs a positive period")
    if t.motion == "circle":
        check(t.radius_m > 0, "target.radius_m", "circle needs a positive radius")
        check(t.period_s != 0, "target.period_s", "circle needs a non-zero period")
    if t.motion == "escape":
        check(t.max_speed_m_s > 0, "target.max_speed_m_s", "must be positive")
    validate_manoeuvre(s, problems)
    if t.motion == "tethered":
        check(t.tether_length_m > 0, "target.tether_length_m", "must be positive")
    if t.motion in ("tethered", "balloon"):
        check(t.mass_kg >= 0, "target.mass_kg", "must be positive (0: from the physics)")
        check(t.net_lift_n >= 0, "target.net_lift_n", "must be positive (0: from the physics)")
        check(t.envelope_mass_kg > 0, "target.envelope_mass_kg", "must be positive")
        check(t.drag_coefficient > 0, "target.drag_coefficient", "must be positive")
        check(t.buffet_lift_coefficient >= 0, "target.buffet_lift_coefficient", "must be >= 0")
        check(t.strouhal_number > 0, "target.strouhal_number", "must be positive")
        if t.net_lift_n == 0 and t.diameter_m > 0 and t.envelope_mass_kg > 0:
            gross = helium_gross_lift_n(t.diameter_m)
            check(
                gross > t.envelope_mass_kg * GRAVITY_M_S2,
                "target.envelope_mass_kg",
                f"{t.envelope_mass_kg} kg is more than a {t.diameter_m} m helium balloon lifts "
                f"({gross / GRAVITY_M_S2 * 1000:.2f} g gross): it would not fly",
            )
    check(t.start_s >= 0, "target.start_s", "must not be negative")
    check(i.position_m[2] > 0, "interceptor.position_m", "must start above ground (z > 0)")
    check(i.size_m > 0, "interceptor.size_m", "must be positive")
    check(i.mass_kg > 0, "interceptor.mass_kg", "must be positive")
    check(i.thrust_to_weight > 1, "interceptor.thrust_to_weight", "must exceed 1")
    check(i.drag_n_s_m >= 0, "interceptor.drag_n_s_m", "must not be negative")
    check(i.drag_area_m2 >= 0, "interceptor.drag_area_m2", "must not be negative")
    check(i.rotor_drag_n_s_m >= 0, "interceptor.rotor_drag_n_s_m", "must not be negative")
    check(
        0 <= i.drag_min_n_s_m <= i.drag_max_n_s_m,
        "interceptor.drag_min_n_s_m",
        "the drawn drag needs 0 <= drag_min_n_s_m <= drag_max_n_s_m",
    )
    check(i.rotor_disc_area_m2 > 0, "interceptor.rotor_disc_area_m2", "must be positive")
    check(i.rate_time_constant_s > 0, "interceptor.rate_time_constant_s", "must be > 0")
    check(i.thrust_time_constant_s > 0, "interceptor.thrust_time_constant_s", "must be > 0")
    check(i.max_rate_deg_s > 0, "interceptor.max_rate_deg_s", "must be positive")
    check(c.width_px >= 16, "camera.width_px", "frame too small (at least 16 px)")
    check(c.height_px >= 16, "camera.height_px", "frame too small (at least 16 px)")
    check(1 <= c.hfov_deg <= 170, "camera.hfov_deg", "must be in [1, 170]")
    check(c.rate_hz > 0, "camera.rate_hz", "must be positive")
    check(c.delay_s >= 0, "camera.delay_s", "must be >= 0")
    check(c.delay_jitter_s >= 0, "camera.delay_jitter_s", "must be >= 0")
    check(c.noise_px >= 0, "camera.noise_px", "must not be negative")
    check(0 <= c.centre_noise_k_px <= 10, "camera.centre_noise_k_px", "must be in [0, 10]")
    check(0 <= c.size_noise_px <= 10, "camera.size_noise_px", "must be in [0, 10] px")
    check(0 <= c.size_noise_rel <= 0.5, "camera.size_noise_rel", "must be in [0, 0.5]")
    check(0 <= c.dropout_probability < 1, "camera.dropout_probability", "must be in [0, 1)")
    check(0 <= c.min_blob_px <= 100, "camera.min_blob_px", "must be in [0, 100] px")
    check(0 <= c.false_probability <= 1, "camera.false_probability", "must be in [0, 1]")
    check(0 < c.false_blob_px <= 100, "camera.false_blob_px", "must be in (0, 100] px")
    check(0 <= c.burst_probability < 1, "camera.burst_probability", "must be in [0, 1)")
    check(c.burst_mean_frames >= 1, "camera.burst_mean_frames", "must be at least 1 frame")
    check(0 <= c.burst_drop_probability <= 1, "camera.burst_drop_probability", "must be in [0, 1]")
    check(s.wind.gust_m_s >= 0, "wind.gust_m_s", "must not be negative")
    check(s.wind.gust_time_constant_s > 0, "wind.gust_time_constant_s", "must be > 0")
    check(s.wind.turbulence_length_m >= 0, "wind.turbulence_length_m", "must not be negative")
    w = s.wind
    check(w.model in WIND_MODELS, "wind.model", f"must be one of {', '.join(WIND_MODELS)}")
    if w.model == "jet":
        check(w.jet_diameter_m > 0, "wind.jet_diameter_m", "must be positive")
        problem = jet_reference_problem(w, t.position_m) if w.jet_diameter_m > 0 else None
        check(problem is None, "wind.jet_source_m", problem or "")
    check(sim.physics_rate_hz >= 500, "sim.physics_rate_hz", "must be at least 500")
    for key, rate in (("sim.control_rate_hz", sim.control_rate_hz), ("camera.rate_hz", c.rate_hz)):
        ratio = sim.physics_rate_hz / rate if rate > 0 else math.nan
        check(
            abs(ratio - round(ratio)) < 1e-9 and round(ratio) >= 1 if rate > 0 else False,
            key,
            f"{rate} Hz must divide the physics rate {sim.physics_rate_hz} Hz",
        )
    check(sim.gyro_noise_rad_s >= 0, "sim.gyro_noise_rad_s", "must not be negative")
    e = s.estimate
    for name in (
        "pos_noise_m",
        "vel_noise_m_s",
        "att_noise_deg",
        "lag_s",
        "att_lag_s",
        "gyro_bias_rad_s",
        "gyro_bias_walk_rad_s_sqrt_s",
        "camera_time_offset_s",
        "camera_stamp_jitter_s",
        "thrust_scale_sigma",
        "command_delay_s",
    ):
        check(getattr(e, name) >= 0, f"estimate.{name}", "must not be negative")
    check(
        e.profile in ESTIMATE_PROFILES,
        "estimate.profile",
        f"must be one of {', '.join(ESTIMATE_PROFILES)}",
    )
    check(0 <= e.heading_noise_deg <= 10, "estimate.heading_noise_deg", "must be in [0, 10] deg")
    for name in ("pos_time_constant_s", "vel_time_constant_s", "att_time_constant_s"):
        check(getattr(e, name) > 0, f"estimate.{name}", "must be > 0")
    check(e.lag_s <= 0.5, "estimate.lag_s", "must be at most 0.5 s")
    check(e.att_lag_s <= 0.5, "estimate.att_lag_s", "must be at most 0.5 s")
    check(e.command_delay_s <= 0.5, "estimate.command_delay_s", "must be at most 0.5 s")
    check(e.att_noise_deg <= 10, "estimate.att_noise_deg", "must be at most 10 degrees")
    check(e.thrust_scale_sigma <= 0.2, "estimate.thrust_scale_sigma", "must be at most 0.2")
    check(
        e.camera_time_offset_s <= 0.05,
        "estimate.camera_time_offset_s",
        "must be at most 0.05 s (a larger offset is a wrong camera delay, camera.delay_s)",
    )
    validate_belief(s, problems)
    each_ok = True
    for k, v in s.gains.items():
        try:
            Gains().replace(**{k: v})
        except GainError as exc:
            each_ok = False
            problems.add(f"gains.{k}", f"key 'gains.{k}': {exc}")
    if each_ok:
        try:
            s.gains_obj()
        except GainError as exc:
            problems.add("gains", str(exc))


MAX_TARGET_ACCEL_M_S2 = 50.0  # a manoeuvre's acceleration beyond this is a typing error


def validate_manoeuvre(s: Scenario, problems: Problems) -> None:
    """The manoeuvring motions' parameters (turn, weave, jink, evade, surge)."""
    t, check = s.target, problems.check
    m = t.motion
    speed = math.sqrt(sum(c * c for c in t.velocity_m_s))
    horizontal = math.hypot(t.velocity_m_s[0], t.velocity_m_s[1])
    lat_ok = abs(t.lateral_accel_m_s2) <= MAX_TARGET_ACCEL_M_S2
    lat_range = f"must be within +-{MAX_TARGET_ACCEL_M_S2} m/s^2"
    if m in ("weave", "surge"):
        check(t.period_s > 0, "target.period_s", f"{m} needs a positive period (its least)")
        check(t.period_max_s >= 0, "target.period_max_s", "must not be negative")
    if m == "turn":
        check(horizontal > 0, "target.velocity_m_s", "a turn needs a horizontal velocity")
        check(lat_ok, "target.lateral_accel_m_s2", lat_range)
    if m == "weave":
        check(
            0 <= t.amplitude_min_m <= t.amplitude_max_m and t.amplitude_max_m > 0,
            "target.amplitude_max_m",
            "a weave needs 0 <= amplitude_min_m <= amplitude_max_m, amplitude_max_m > 0",
        )
    if m == "jink":
        check(t.trigger_range_m > 0, "target.trigger_range_m", "a jink needs a positive range")
        check(t.jink_speed_m_s > 0, "target.jink_speed_m_s", "must be positive")
        check(
            0 < t.jink_accel_m_s2 <= MAX_TARGET_ACCEL_M_S2,
            "target.jink_accel_m_s2",
            f"must be in (0, {MAX_TARGET_ACCEL_M_S2}] m/s^2",
        )
    if m == "evade":
        check(
            0 < t.lateral_accel_m_s2 <= MAX_TARGET_ACCEL_M_S2,
            "target.lateral_accel_m_s2",
            f"evasion needs a lateral acceleration in (0, {MAX_TARGET_ACCEL_M_S2}] m/s^2",
        )
        check(t.trigger_range_m >= 0, "target.trigger_range_m", "must not be negative")
        check(t.max_speed_m_s > 0, "target.max_speed_m_s", "must be positive")
    if m == "surge":
        check(speed > 0, "target.velocity_m_s", "a surge needs a velocity to change")
        check(
            0 <= t.speed_change_m_s <= speed / 2,
            "target.speed_change_m_s",
            f"must be in [0, {speed / 2:g}] m/s (half the speed: it never flies backwards)",
        )
    check(t.side in (-1.0, 0.0, 1.0), "target.side", "must be 1 (left), -1 (right) or 0 (drawn)")


# how far a calibration may be from the camera flown before it is a different camera (the
# scenario forgot to state the belief): field of view and mount angles
BELIEF_HFOV_REL = 0.1
BELIEF_MOUNT_DEG = 10.0


def validate_belief(s: Scenario, problems: Problems) -> None:
    """The [belief] table's ranges, and a calibration that describes the camera flown."""
    b, c, check = s.belief, s.camera, problems.check
    check(0.02 <= b.target_diameter_m <= 3.0, "belief.target_diameter_m", "must be in [0.02, 3] m")
    check(20 <= b.camera_hfov_deg <= 170, "belief.camera_hfov_deg", "must be in [20, 170] deg")
    check(
        -90 <= b.camera_mount_pitch_deg <= 90,
        "belief.camera_mount_pitch_deg",
        "must be in [-90, 90]",
    )
    check(
        -180 <= b.camera_mount_roll_deg <= 180,
        "belief.camera_mount_roll_deg",
        "must be in [-180, 180]",
    )
    check(0.05 <= b.hover_thrust <= 0.95, "belief.hover_thrust", "must be in [0.05, 0.95]")
    check(
        0.1 <= b.target_accel_noise_m_s2 <= 30.0,
        "belief.target_accel_noise_m_s2",
        "must be in [0.1, 30] m/s^2",
    )
    for side, spec, prefix in (("belief", b, "camera_"), ("camera", c, "")):
        for name in ("principal_offset_u_px", "principal_offset_v_px"):
            v = getattr(spec, prefix + name)
            check(abs(v) <= 50, f"{side}.{prefix}{name}", "must be within 50 px of the centre")
        for name in ("k1", "k2", "p1", "p2"):
            v = getattr(spec, prefix + name)
            limit = 1.0 if name in ("k1", "k2") else 0.05
            check(abs(v) <= limit, f"{side}.{prefix}{name}", f"must be in [-{limit}, {limit}]")
        off = getattr(spec, prefix + "offset_m")
        check(all(abs(x) <= 1.0 for x in off), f"{side}.{prefix}offset_m", "must be within 1 m")
    if 1 <= c.hfov_deg <= 170:
        check(
            abs(b.camera_hfov_deg / c.hfov_deg - 1.0) <= BELIEF_HFOV_REL,
            "belief.camera_hfov_deg",
            f"{b.camera_hfov_deg} deg calibrates a different lens than the camera's "
            f"{c.hfov_deg} deg: state the operator's calibration in [belief]",
        )
    for name in ("mount_pitch_deg", "mount_roll_deg"):
        believed, true = getattr(b, "camera_" + name), getattr(c, name)
        check(
            abs(believed - true) <= BELIEF_MOUNT_DEG,
            f"belief.camera_{name}",
            f"{believed} deg is not the mount flown ({true} deg): state it in [belief]",
        )
