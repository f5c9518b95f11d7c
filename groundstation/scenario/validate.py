"""The value checks of a parsed scenario (ranges, consistency between sections, physics):
every problem is recorded, none stops the others from being checked."""

from __future__ import annotations

import math

from onboard.constants import GRAVITY_M_S2
from onboard.gains import GainError, Gains

from .physics import helium_gross_lift_n, jet_reference_problem
from .problems import Problems
from .specs import MOTIONS, WIND_MODELS, Scenario


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
