"""The proposed law: proportional navigation on the velocity angles with the k_a speed ramp
(paper eqs. 8-9, 14, 17), its field-of-view guard and pursuit bias near the image's edges, and
the midcourse ZEM-nulling term far away (DESIGN.md §3 steps 4-7)."""

from __future__ import annotations

import math

import numpy as np

from ..datatypes import GRAVITY_M_S2
from ..gains import GainIndex, Gains, pack_gains
from ..jit import kernel
from .guidance_io import GuidanceInput, GuidanceOutput
from .los import _f3, _max, _min, angles_floats, hypot2, saturate3, saturate_norm

# what these kernels call from other files (their cache is dropped when one changes): los.py's
# kernels and the gains' declaration (png_floats's indices)
_USES = (hypot2, pack_gains)


def ramped_speed(speed_m_s: float, gains: Gains, dt_s: float) -> float:
    """|v_d| = |v| + a_t dt (paper eq. 14): the tangential acceleration a_t is k_a, tapering
    near v_max as a speed hold, a_t = clip(k_brake (v_max - |v|), -k_a, k_a).

    Asking for v_max outright (eq. 17 divides by dt) would turn centimetres per second of
    overspeed into a saturated brake and then a full k_a again: the vehicle pitches back and
    forth by atan(k_a / g) and its flight path walks off, which PN cannot see from far away."""
    return ramped_speed_floats(speed_m_s, gains.k_brake, gains.v_max, gains.k_a, dt_s)


@kernel(
    "UniTuple(float64, 3)(float64, float64, float64, float64, float64, float64, float64, "
    "float64, float64, float64)"
)
def believed_drag_floats(
    v0: float,
    v1: float,
    v2: float,
    z0: float,
    z1: float,
    z2: float,
    d0: float,
    d1: float,
    d2: float,
    k_drag: float,
) -> tuple[float, float, float]:
    """The specific force (m/s^2, ENU) of drag and disturbance the loop believes acts on it:
    its airframe's drag in still air as PX4's EKF2 models it, -k_drag times the velocity's
    part in the rotor plane (v - (v . z) z, z the thrust axis; k_drag an operator parameter,
    EKF2_MCOEF), plus the disturbance observer's d^ = (d0, d1, d2), which is what that model
    leaves unexplained (drag beyond the believed one, wind). The model part follows the
    attitude at once; the observer's acts as an integral on the rest."""
    vz = v0 * z0 + v1 * z1 + v2 * z2
    return (
        d0 - k_drag * (v0 - vz * z0),
        d1 - k_drag * (v1 - vz * z1),
        d2 - k_drag * (v2 - vz * z2),
    )


@kernel("float64(float64, float64, float64, float64, float64, float64)", uses=_USES)
def drag_feedforward_floats(
    u0: float, u1: float, u2: float, d0: float, d1: float, d2: float
) -> float:
    """The along-track acceleration (m/s^2, >= 0) the speed ramp adds so that the vehicle
    gains speed at a_t against drag (eq. 14 with drag): the believed drag and disturbance
    d = (d0, d1, d2) (:func:`believed_drag_floats`) against the unit velocity u. Never
    negative: a tailwind does not brake."""
    return _max(-(d0 * u0 + d1 * u1 + d2 * u2), 0.0)


@kernel("float64(float64, float64, float64, float64, float64)", uses=_USES)
def ramped_speed_floats(speed: float, k_brake: float, v_max: float, k_a: float, dt: float) -> float:
    """:func:`ramped_speed` in floats (compiled)."""
    a_t = _min(_max(k_brake * (v_max - speed), -k_a), k_a)
    return speed + a_t * dt


def accel_toward_velocity(v_d: np.ndarray, v: np.ndarray, gains: Gains, dt_s: float):
    """a_d = (v_d - v) / dt, saturated to a_max (paper eq. 17)."""
    return saturate_norm((v_d - v) / dt_s, gains.a_max)


_PITCH_LIMIT_RAD = math.radians(60.0)


@kernel("float64(float64, float64, float64)", uses=_USES)
def min_pitch_rad(los_elev_rad: float, top_edge_rad: float, margin_rad: float) -> float:
    """Lowest body pitch (nose up +, rad) that keeps a LOS at elevation ``los_elev_rad`` at
    least ``margin_rad`` below the image's top edge, which sits ``top_edge_rad`` above body x
    (clipped to +-60 deg)."""
    lo = los_elev_rad - (top_edge_rad - margin_rad)
    return _min(_max(lo, -_PITCH_LIMIT_RAD), _PITCH_LIMIT_RAD)


def fov_guard(a_d: np.ndarray, inp: GuidanceInput, gains: Gains) -> np.ndarray:
    """Field-of-view guard on a desired acceleration (not in the paper; docs/core.md, "Field
    of view").

    A thrust-vectoring vehicle flies a forward acceleration a_f by pitching its nose down by
    atan(a_f / (g + a_z)) (eqs. 16, 18), and the strapdown camera pitches with it: the speed
    ramp's k_a moves a target that sits high in the image off its top edge. The guard caps
    a_f, the component of a_d along the camera's horizontal heading, at the value whose steady
    pitch keeps the LOS ``fov_margin`` degrees below the top edge (:func:`min_pitch_rad`), and
    at no less than 0: it limits the pitch-down, it never brakes (braking bled the forward
    speed off, the flight path went nearly vertical and its azimuth wandered). The vertical
    and lateral components, which PNG turns with, are untouched; so is a target low in the
    image (forcing a nose-down pitch would fight PNG's endgame); the pursuit bias
    (:func:`pursuit_weight`) does the rest. ``fov_margin = 0`` switches it off.
    """
    a0, a1, a2 = _f3(a_d)
    R = inp.R_WC
    out = fov_guard_floats(
        a0, a1, a2, inp.fov_edges_rad[0], float(R[0, 2]), float(R[1, 2]), inp.los_elev_rad,
        math.radians(gains.fov_margin), gains.a_max,
    )  # fmt: skip
    return a_d if out[0] == 0.0 else np.array(out[1:])


@kernel(
    "UniTuple(float64, 4)(float64, float64, float64, float64, float64, float64, float64, "
    "float64, float64)",
    uses=_USES,
)
def fov_guard_floats(
    a0: float,
    a1: float,
    a2: float,
    top_edge_rad: float,
    heading_x: float,
    heading_y: float,
    los_elev_rad: float,
    margin_rad: float,
    a_max: float,
) -> tuple[float, float, float, float]:
    """:func:`fov_guard` in floats (compiled): (1, guarded a_d) or (0, a_d untouched);
    ``heading_x/y``: the camera axis's east and north components (R_WC[:2, 2])."""
    if margin_rad <= 0.0 or not math.isfinite(top_edge_rad):
        return 0.0, a0, a1, a2
    hn = hypot2(heading_x, heading_y)
    if hn < 1e-6:  # camera looking straight up or down: no heading to pitch along
        return 0.0, a0, a1, a2
    h0, h1 = heading_x / hn, heading_y / hn
    lo = min_pitch_rad(los_elev_rad, top_edge_rad, margin_rad)
    a_f = a0 * h0 + a1 * h1 + a2 * 0.0
    gz = _max(GRAVITY_M_S2 + a2, 0.1 * GRAVITY_M_S2)
    a_f_max = _max(-gz * math.tan(lo), 0.0)  # limit the pitch-down, never brake
    if a_f <= a_f_max:
        return 0.0, a0, a1, a2
    c = a_f_max - a_f
    g0, g1, g2 = saturate3(a0 + c * h0, a1 + c * h1, a2 + c * 0.0, a_max)
    return 1.0, g0, g1, g2


def edge_margin_rad(inp: GuidanceInput) -> float:
    """Angle (rad) between the LOS and the nearer of the image's top and bottom edges, with
    the camera's current pitch (its optical axis elevation; a level-rolled camera): negative
    when the LOS is outside the vertical FOV, nan when the FOV edges are unknown."""
    axis = inp.R_WC[:, 2].tolist()
    return edge_margin_floats(*inp.fov_edges_rad, *axis, inp.los_elev_rad)


@kernel("float64(float64, float64, float64, float64, float64, float64)", uses=_USES)
def edge_margin_floats(
    top: float, bottom: float, ax0: float, ax1: float, ax2: float, los_elev_rad: float
) -> float:
    """:func:`edge_margin_rad` in floats (compiled); (ax0, ax1, ax2) the camera axis (ENU)."""
    if not (math.isfinite(top) and math.isfinite(bottom)):
        return math.nan
    cam_elev = math.atan2(ax2, hypot2(ax0, ax1))
    half = 0.5 * (top - bottom)
    return _min(cam_elev + half - los_elev_rad, los_elev_rad - (cam_elev - half))


def pursuit_weight(inp: GuidanceInput, gains: Gains) -> float:
    """Weight in [0, 1] of the pursuit bias: 0 while the LOS is more than ``pur_zone`` degrees
    inside the top and bottom edges, rising linearly to 1 at the edge (0 if ``pur_zone`` = 0)."""
    axis = inp.R_WC[:, 2].tolist()
    top, bottom = inp.fov_edges_rad
    return pursuit_floats(
        math.radians(gains.pur_zone), gains.k_pur, top, bottom, *axis, inp.los_elev_rad
    )


@kernel(
    "float64(float64, float64, float64, float64, float64, float64, float64, float64)", uses=_USES
)
def pursuit_floats(
    pur_zone_rad: float,
    k_pur: float,
    top: float,
    bottom: float,
    ax0: float,
    ax1: float,
    ax2: float,
    los_elev_rad: float,
) -> float:
    """:func:`pursuit_weight` in floats (compiled)."""
    if pur_zone_rad <= 0.0 or k_pur <= 0.0:
        return 0.0
    m = edge_margin_floats(top, bottom, ax0, ax1, ax2, los_elev_rad)
    if not math.isfinite(m):
        return 0.0
    return _min(_max(1.0 - m / pur_zone_rad, 0.0), 1.0)


def midcourse_weight(range_m: float, gains: Gains) -> float:
    """Weight in [0, 1] of the midcourse ZEM-nulling term: 0 within ``r_mid`` metres, rising
    linearly to 1 at twice ``r_mid`` (0 when ``tau_zem`` = 0 or the range is unknown)."""
    return midcourse_floats(range_m, gains.tau_zem, gains.r_mid)


@kernel("float64(float64, float64, float64)", uses=_USES)
def midcourse_floats(range_m: float, tau_zem: float, r_mid: float) -> float:
    """:func:`midcourse_weight` in floats (compiled)."""
    if tau_zem <= 0.0 or not math.isfinite(range_m):
        return 0.0
    return _min(_max(range_m / r_mid - 1.0, 0.0), 1.0)


def zem_nulling_accel(inp: GuidanceInput, gains: Gains) -> np.ndarray:
    """Midcourse acceleration a = -v_perp / tau_zem (m/s^2, not in the paper), v_perp the
    vehicle's velocity relative to the target normal to the LOS.

    With t_go = R / V_c the zero-effort miss normal to the LOS is ZEM = -v_perp t_go, so this
    is a = ZEM / (tau_zem t_go): the miss decays as exp(-t / tau_zem) whatever the range, where
    PN (a = K V_c q') lets it decay only as (t_go / t_go0)^K. It uses absolute directions
    (LOS, velocity), not the LOS rate, so the attitude estimate's error enters as an angle
    (R x 0.2 deg of ZEM), not differentiated. The target's velocity is the DKF's, shrunk toward
    zero by its own uncertainty (|v_t|^2 / (|v_t|^2 + tr P_v)): far away it is barely
    observable, and an unobservable estimate must not steer."""
    vt = inp.target_vel_enu_m_s
    t0, t1, t2 = (math.nan,) * 3 if vt is None else _f3(vt)
    return np.array(
        zem_floats(
            *_f3(inp.velocity_enu_m_s),
            vt is not None,
            t0,
            t1,
            t2,
            inp.target_vel_var_m2_s2,
            *_f3(inp.los_enu),
            gains.tau_zem,
        )
    )


@kernel(
    "UniTuple(float64, 3)(float64, float64, float64, boolean, float64, float64, float64, "
    "float64, float64, float64, float64, float64)"
)
def zem_floats(
    v0: float,
    v1: float,
    v2: float,
    has_vt: bool,
    t0: float,
    t1: float,
    t2: float,
    var: float,
    n0: float,
    n1: float,
    n2: float,
    tau_zem: float,
) -> tuple[float, float, float]:
    """:func:`zem_nulling_accel` in floats (compiled): velocity v, the target's t (when
    ``has_vt``) with its variance, the LOS n."""
    if has_vt:
        vt2 = t0 * t0 + t1 * t1 + t2 * t2
        shrink = vt2 / (vt2 + var) if math.isfinite(var) and vt2 + var > 0.0 else 0.0
        v0, v1, v2 = v0 - shrink * t0, v1 - shrink * t1, v2 - shrink * t2
    vn = v0 * n0 + v1 * n1 + v2 * n2
    k = -1.0 / tau_zem
    return (v0 - vn * n0) * k, (v1 - vn * n1) * k, (v2 - vn * n2) * k


def png_law(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    """The proposed law: PNG on the velocity angles plus the k_a speed ramp (eqs. 8-9, 14, 17)."""
    a0, a1, a2, sigma_y, sigma_z, hovering = png_command(
        inp.dt_s, _f3(inp.los_enu), inp.los_elev_rad, inp.d_los_elev_rad, inp.d_los_azim_rad,
        _f3(inp.velocity_enu_m_s), inp.R_WC, inp.fov_edges_rad, inp.range_m,
        inp.target_vel_enu_m_s, inp.target_vel_var_m2_s2, gains, inp.disturbance_enu_m_s2,
        inp.speed_cap_m_s,
    )  # fmt: skip
    return GuidanceOutput(np.array((a0, a1, a2)), sigma_y, sigma_z, hovering)


def png_command(
    dt_s: float,
    los_enu: tuple[float, float, float],
    los_elev_rad: float,
    d_los_elev_rad: float,
    d_los_azim_rad: float,
    velocity_enu_m_s: tuple[float, float, float],
    R_WC: np.ndarray,
    fov_edges_rad: tuple[float, float],
    range_m: float,
    target_vel_enu_m_s: np.ndarray | None,
    target_vel_var_m2_s2: float,
    gains: Gains,
    disturbance_enu_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0),
    speed_cap_m_s: float = math.inf,
) -> tuple[float, float, float, float, float, bool]:
    """:func:`png_law` from floats (:class:`GuidanceInput`'s fields, the LOS, the velocity
    and the believed drag and disturbance as three floats each; the loop's tick calls it so):
    (a_d ENU m/s^2 as three floats, sigma_y, sigma_z (nan while hovering), hovering).
    ``speed_cap_m_s`` below ``v_max`` is the speed ramp's reference instead (eq. 14)."""
    e0, e1, e2 = disturbance_enu_m_s2
    l0, l1, l2 = los_enu
    v0, v1, v2 = velocity_enu_m_s
    vt = target_vel_enu_m_s
    t0, t1, t2 = (math.nan,) * 3 if vt is None else _f3(vt)
    top, bottom = fov_edges_rad
    R = R_WC
    G = gains.packed
    if speed_cap_m_s < gains.v_max:
        G = G.copy()
        G[GainIndex.v_max] = speed_cap_m_s
    a0, a1, a2, sigma_y, sigma_z, hovering = png_floats(
        dt_s, l0, l1, l2, los_elev_rad, d_los_elev_rad, d_los_azim_rad, v0, v1, v2,
        float(R[0, 2]), float(R[1, 2]), float(R[2, 2]), top, bottom, range_m, vt is not None,
        t0, t1, t2, target_vel_var_m2_s2, e0, e1, e2, G,
    )  # fmt: skip
    if hovering != 0.0:  # the angles are math.nan itself (telemetry compares equal)
        return a0, a1, a2, math.nan, math.nan, True
    return a0, a1, a2, sigma_y, sigma_z, False


@kernel(
    "UniTuple(float64, 6)(float64, float64, float64, float64, float64, float64, float64, "
    "float64, float64, float64, float64, float64, float64, float64, float64, float64, boolean, "
    "float64, float64, float64, float64, float64, float64, float64, float64[::1])",
    uses=_USES,
)
def png_floats(
    dt: float,
    l0: float,
    l1: float,
    l2: float,
    q_y: float,
    dq_y: float,
    dq_z: float,
    v0: float,
    v1: float,
    v2: float,
    ax0: float,
    ax1: float,
    ax2: float,
    top: float,
    bottom: float,
    range_m: float,
    has_vt: bool,
    t0: float,
    t1: float,
    t2: float,
    var_v: float,
    e0: float,
    e1: float,
    e2: float,
    G: np.ndarray,
) -> tuple[float, float, float, float, float, float]:
    """:func:`png_law` in floats (compiled): the hold dt (s), the LOS n_t and its elevation
    q_y, the LOS change (dq_y, dq_z), the velocity v, the camera axis (R_WC[:, 2]), the
    image's (top, bottom) edges, the DKF's range and target velocity (with its variance), the
    believed drag and disturbance (e0, e1, e2) (:func:`believed_drag_floats`) and the gains
    ``G`` (:func:`~onboard.gains.pack_gains`); returns (a_d, sigma_y, sigma_z, 1 when hovering
    else 0).

    The speed ramp's tangential acceleration is net of drag: the along-track drag feed-forward
    (:func:`drag_feedforward_floats`) is added after eq. 17's saturation, so that PN keeps its
    whole a_max across the velocity, and before the FOV guard, which sees the whole pitch."""
    v_min, k_a, a_max = G[GainIndex.v_min], G[GainIndex.k_a], G[GainIndex.a_max]
    K_y, K_z, tau_zem, r_mid = (
        G[GainIndex.K_y],
        G[GainIndex.K_z],
        G[GainIndex.tau_zem],
        G[GainIndex.r_mid],
    )
    pur_zone, k_pur = math.radians(G[GainIndex.pur_zone]), G[GainIndex.k_pur]
    k_brake, v_max = G[GainIndex.k_brake], G[GainIndex.v_max]
    fov_margin = math.radians(G[GainIndex.fov_margin])
    speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if speed < v_min or v0 * l0 + v1 * l1 + v2 * l2 < 0.0:
        # below v_min the velocity angles are undefined (§3.4), and flying away from the
        # target PN has nothing to turn (a target behind has no LOS rate) while the speed
        # ramp pushes along the velocity: accelerate along the LOS
        a0, a1, a2 = saturate3(k_a * l0, k_a * l1, k_a * l2, a_max)
        _, a0, a1, a2 = fov_guard_floats(a0, a1, a2, top, ax0, ax1, q_y, fov_margin, a_max)
        return a0, a1, a2, math.nan, math.nan, 1.0
    u0, u1, u2 = v0 / speed, v1 / speed, v2 / speed
    sigma_y, sigma_z = angles_floats(u0, u1, u2)
    # far away PN's LOS-rate term is mostly noise (v/R small): it fades out as the midcourse
    # ZEM-nulling term fades in (docs/core.md, "Midcourse ZEM nulling")
    w_mid = midcourse_floats(range_m, tau_zem, r_mid)
    pn = 1.0 - w_mid
    sigma_yd = sigma_y + pn * K_y * dq_y
    sigma_zd = sigma_z + pn * K_z * dq_z
    ce = math.cos(sigma_yd)  # n_d (eq. 9, as direction_from_angles)
    n0, n1, n2 = ce * math.sin(sigma_zd), ce * math.cos(sigma_zd), math.sin(sigma_yd)
    w = pursuit_floats(pur_zone, k_pur, top, bottom, ax0, ax1, ax2, q_y)
    if w > 0.0:  # near the image's top or bottom edge: turn toward the LOS (pursuit)
        k = w * k_pur * dt
        n0, n1, n2 = n0 + k * (l0 - u0), n1 + k * (l1 - u1), n2 + k * (l2 - u2)
        nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        n0, n1, n2 = n0 / nn, n1 / nn, n2 / nn
    sp = ramped_speed_floats(speed, k_brake, v_max, k_a, dt)
    d0, d1, d2 = sp * n0, sp * n1, sp * n2  # v_d
    if w_mid > 0.0:  # far away: null the ZEM (midcourse), PN's endgame takes over within r_mid
        k = w_mid * dt
        z0, z1, z2 = zem_floats(v0, v1, v2, has_vt, t0, t1, t2, var_v, l0, l1, l2, tau_zem)
        d0, d1, d2 = d0 + k * z0, d1 + k * z1, d2 + k * z2
    # eq. 17, saturated, the drag feed-forward along the velocity, then the FOV guard
    a0, a1, a2 = saturate3((d0 - v0) / dt, (d1 - v1) / dt, (d2 - v2) / dt, a_max)
    a_drag = _min(drag_feedforward_floats(u0, u1, u2, e0, e1, e2), a_max)
    a0, a1, a2 = a0 + a_drag * u0, a1 + a_drag * u1, a2 + a_drag * u2
    lim = a_max + a_drag
    _, a0, a1, a2 = fov_guard_floats(a0, a1, a2, top, ax0, ax1, q_y, fov_margin, lim)
    return a0, a1, a2, sigma_y, sigma_z, 0.0
