"""Guidance: line of sight from the image, LOS/velocity angles and the guidance laws that
turn them into a desired acceleration (paper eqs. 5-9, 14, 17; DESIGN.md §3 steps 2-7, §5).

All vectors are world ENU. A law is a function ``(GuidanceInput, Gains) -> GuidanceOutput``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..datatypes import GRAVITY_M_S2
from ..enums import GuidanceLaw as Law
from ..gains import Gains
from ..geometry import wrap_pi
from ..jit import kernel


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class GuidanceInput:
    """What a guidance law sees at one control tick."""

    dt_s: float
    los_enu: np.ndarray  # unit LOS n_t (eq. 5)
    los_elev_rad: float  # q_y (eq. 6)
    los_azim_rad: float  # q_z (eq. 6), from +y toward +x
    d_los_elev_rad: float  # q_y(k) - q_y(k-1)
    d_los_azim_rad: float  # wrapped to (-pi, pi]
    velocity_enu_m_s: np.ndarray
    e_norm: tuple[float, float]  # normalised image error e / f
    R_WC: np.ndarray  # camera -> world
    # elevation (rad) of the image's (top, bottom) edges above the body x axis of a level
    # body: mount pitch +- half the vertical FOV; nan switches the FOV-aware terms off
    fov_edges_rad: tuple[float, float] = (math.nan, math.nan)
    # the DKF's range along the LOS (m) and the target's velocity (ENU, m/s) with the trace of
    # its covariance (m^2/s^2); nan / None when unknown (the midcourse term is then off)
    range_m: float = math.nan
    target_vel_enu_m_s: np.ndarray | None = None
    target_vel_var_m2_s2: float = math.nan
    # the specific force (m/s^2, ENU) of the drag the loop believes its airframe has plus the
    # disturbance observer's d^ (:func:`believed_drag_floats`): the speed ramp overcomes its
    # along-track part
    disturbance_enu_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class GuidanceOutput:
    accel_desired_enu_m_s2: np.ndarray  # a_d, saturated (eq. 17)
    vel_elev_rad: float  # sigma_y (eq. 7), nan when hovering
    vel_azim_rad: float  # sigma_z (eq. 7), nan when hovering
    hovering: bool  # |v| < v_min: flew along the LOS


def line_of_sight(e_norm_x: float, e_norm_y: float, R_WC: np.ndarray) -> np.ndarray:
    """n_t = R_WB R_BC r_C / |r_C|, r_C = (e_x/f, e_y/f, 1) (paper eq. 5): :func:`los_floats`."""
    R = np.asarray(R_WC, dtype=np.float64)
    if R.shape != (3, 3):  # the kernel reads nine entries unchecked
        raise ValueError(f"R_WC must be 3x3, not {R.shape}")
    return np.array(los_floats(e_norm_x, e_norm_y, R if R.flags.writeable else R.copy()))


@kernel("UniTuple(float64, 3)(float64, float64, float64[:, :])")
def los_floats(e_norm_x: float, e_norm_y: float, R_WC: np.ndarray) -> tuple[float, float, float]:
    """:func:`line_of_sight` in floats (compiled). The product's and the norm's sums are
    taken in index order: numpy's product goes to BLAS, whose kernel (and so its rounding,
    FMA or not) depends on the CPU, and the same seeds must fly the same sortie anywhere."""
    r0 = R_WC[0, 0] * e_norm_x + R_WC[0, 1] * e_norm_y + R_WC[0, 2]
    r1 = R_WC[1, 0] * e_norm_x + R_WC[1, 1] * e_norm_y + R_WC[1, 2]
    r2 = R_WC[2, 0] * e_norm_x + R_WC[2, 1] * e_norm_y + R_WC[2, 2]
    n = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    return r0 / n, r1 / n, r2 / n


_SPLITTER = 134217729.0  # 2**27 + 1 (Veltkamp): splits a double into two 26-bit halves
_DBL_MIN = 2.2250738585072014e-308  # the smallest normal double


@kernel("float64(float64, float64)")
def _min(a: float, b: float) -> float:
    """Python's ``min(a, b)`` to the letter (``a`` unless ``b < a``; so NaN as Python's)."""
    return b if b < a else a


@kernel("float64(float64, float64)")
def _max(a: float, b: float) -> float:
    """Python's ``max(a, b)`` to the letter (``a`` unless ``b > a``)."""
    return b if b > a else a


@kernel("UniTuple(float64, 2)(float64)")
def _exact_square(x: float) -> tuple[float, float]:
    """x * x as hi + lo with lo the exact rounding error (Dekker's product)."""
    p = x * x
    c = _SPLITTER * x
    xh = c - (c - x)
    xl = x - xh
    return p, ((xh * xh - p) + 2.0 * (xh * xl)) + xl * xl


@kernel("float64(float64, float64)")
def hypot2(x: float, y: float) -> float:
    """sqrt(x^2 + y^2) as CPython's ``math.hypot`` computes it, to the bit (its correctly
    rounded vector norm: scaled by a power of two, squares and sums carried exactly in two
    parts, one Newton correction), so a kernel gives the numbers the Python code gave; libm's
    ``hypot``, which numba calls, differs in the last bit in about 0.2 % of inputs. Checked
    equal to ``math.hypot`` on millions of seeded inputs (tests/test_guidance_kernels.py);
    only where both arguments are subnormal (below 2.2e-308) may it differ."""
    x = abs(x)
    y = abs(y)
    if math.isinf(x) or math.isinf(y):
        return math.inf
    if math.isnan(x) or math.isnan(y):
        return math.nan
    m = x if x > y else y
    if m == 0.0:
        return 0.0
    post = 1.0
    e = math.frexp(m)[1]
    if e < -1023:  # subnormal: scale up to normals first (2^-e would overflow)
        x, y, post = x / _DBL_MIN, y / _DBL_MIN, _DBL_MIN
        e = math.frexp(m / _DBL_MIN)[1]
    scale = math.ldexp(1.0, -e)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    hi, lo = _exact_square(x * scale)
    s = csum + hi
    frac2 += hi - (s - csum)
    csum = s
    frac1 += lo
    hi, lo = _exact_square(y * scale)
    s = csum + hi
    frac2 += hi - (s - csum)
    csum = s
    frac1 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    hi, lo = _exact_square(h)
    s = csum - hi
    frac2 += -hi - (s - csum)
    csum = s
    frac1 -= lo
    h += (csum - 1.0 + (frac1 + frac2)) / (2.0 * h)
    return post * (h / scale)


@kernel("UniTuple(float64, 2)(float64, float64, float64)")
def angles_floats(x: float, y: float, z: float) -> tuple[float, float]:
    """:func:`direction_angles` of (x, y, z) (compiled)."""
    return math.atan2(z, hypot2(x, y)), math.atan2(x, y)


def direction_angles(n: np.ndarray) -> tuple[float, float]:
    """(elevation, azimuth) of a direction: q_y = atan2(n_z, hypot(n_x, n_y)),
    q_z = atan2(n_x, n_y) (paper eqs. 6-7 with atan2, DESIGN §3 step 3)."""
    return angles_floats(float(n[0]), float(n[1]), float(n[2]))


def direction_from_angles(elev_rad: float, azim_rad: float) -> np.ndarray:
    """n_vd = (cos s_y sin s_z, cos s_y cos s_z, sin s_y) (paper eq. 9)."""
    ce = math.cos(elev_rad)
    return np.array([ce * math.sin(azim_rad), ce * math.cos(azim_rad), math.sin(elev_rad)])


def saturate_norm(vec: np.ndarray, limit: float) -> np.ndarray:
    """Scale ``vec`` down to norm ``limit`` if it is longer (keeps its direction)."""
    n = math.sqrt(float(vec @ vec))
    if n > limit > 0.0:
        return vec * (limit / n)
    return vec


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


@kernel("float64(float64, float64, float64, float64, float64, float64)")
def drag_feedforward_floats(
    u0: float, u1: float, u2: float, d0: float, d1: float, d2: float
) -> float:
    """The along-track acceleration (m/s^2, >= 0) the speed ramp adds so that the vehicle
    gains speed at a_t against drag (eq. 14 with drag): the believed drag and disturbance
    d = (d0, d1, d2) (:func:`believed_drag_floats`) against the unit velocity u. Never
    negative: a tailwind does not brake."""
    return _max(-(d0 * u0 + d1 * u1 + d2 * u2), 0.0)


@kernel("float64(float64, float64, float64, float64, float64)")
def ramped_speed_floats(speed: float, k_brake: float, v_max: float, k_a: float, dt: float) -> float:
    """:func:`ramped_speed` in floats (compiled)."""
    a_t = _min(_max(k_brake * (v_max - speed), -k_a), k_a)
    return speed + a_t * dt


def accel_toward_velocity(v_d: np.ndarray, v: np.ndarray, gains: Gains, dt_s: float):
    """a_d = (v_d - v) / dt, saturated to a_max (paper eq. 17)."""
    return saturate_norm((v_d - v) / dt_s, gains.a_max)


def normal_component(accel: np.ndarray, velocity: np.ndarray) -> float:
    """Magnitude of the part of ``accel`` normal to ``velocity`` (m/s^2)."""
    return normal_floats(*_f3(accel), *_f3(velocity))


@kernel("float64(float64, float64, float64, float64, float64, float64)")
def normal_floats(a0: float, a1: float, a2: float, v0: float, v1: float, v2: float) -> float:
    """:func:`normal_component` in floats (compiled)."""
    vv = v0 * v0 + v1 * v1 + v2 * v2
    if vv < 1e-12:
        return math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    k = (a0 * v0 + a1 * v1 + a2 * v2) / vv
    n0, n1, n2 = a0 - k * v0, a1 - k * v1, a2 - k * v2
    return math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)


def _hover_start(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    # Below v_min the velocity angles are undefined: accelerate along the LOS (DESIGN §3.4).
    a_d = saturate_norm(gains.k_a * inp.los_enu, gains.a_max)
    return GuidanceOutput(a_d, math.nan, math.nan, True)


_PITCH_LIMIT_RAD = math.radians(60.0)


@kernel("float64(float64, float64, float64)")
def min_pitch_rad(los_elev_rad: float, top_edge_rad: float, margin_rad: float) -> float:
    """Lowest body pitch (nose up +, rad) that keeps a LOS at elevation ``los_elev_rad`` at
    least ``margin_rad`` below the image's top edge, which sits ``top_edge_rad`` above body x
    (clipped to +-60 deg)."""
    lo = los_elev_rad - (top_edge_rad - margin_rad)
    return _min(_max(lo, -_PITCH_LIMIT_RAD), _PITCH_LIMIT_RAD)


def fov_guard(a_d: np.ndarray, inp: GuidanceInput, gains: Gains) -> np.ndarray:
    """Field-of-view guard on a desired acceleration (not in the paper; README "Field of
    view").

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


def _f3(x) -> tuple[float, float, float]:
    """A 3-vector (ndarray or sequence) as three floats."""
    if isinstance(x, np.ndarray):
        x0, x1, x2 = x.tolist()
        return x0, x1, x2
    return float(x[0]), float(x[1]), float(x[2])


@kernel("UniTuple(float64, 3)(float64, float64, float64, float64)")
def saturate3(x0: float, x1: float, x2: float, limit: float) -> tuple[float, float, float]:
    """:func:`saturate_norm` in floats (the same operations; compiled)."""
    n = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if n > limit > 0.0:
        g = limit / n
        return x0 * g, x1 * g, x2 * g
    return x0, x1, x2


@kernel(
    "UniTuple(float64, 4)(float64, float64, float64, float64, float64, float64, float64, "
    "float64, float64)"
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


@kernel("float64(float64, float64, float64, float64, float64, float64)")
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


@kernel("float64(float64, float64, float64, float64, float64, float64, float64, float64)")
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


@kernel("float64(float64, float64, float64, float64)")
def smooth_los_change(prev_rad: float, dq_rad: float, dt_s: float, tau_s: float) -> float:
    """One step of a first-order low-pass on the per-tick LOS change Delta q (eq. 8's input):
    prev + dt / (tau + dt) (dq - prev). Far away the LOS rate |v| sin(angle) / R is small and
    Delta q is mostly image noise; ``tau_s = 0`` passes Delta q through unchanged."""
    if tau_s <= 0.0 or not math.isfinite(prev_rad):
        return dq_rad
    return prev_rad + (dt_s / (tau_s + dt_s)) * (dq_rad - prev_rad)


def midcourse_weight(range_m: float, gains: Gains) -> float:
    """Weight in [0, 1] of the midcourse ZEM-nulling term: 0 within ``r_mid`` metres, rising
    linearly to 1 at twice ``r_mid`` (0 when ``tau_zem`` = 0 or the range is unknown)."""
    return midcourse_floats(range_m, gains.tau_zem, gains.r_mid)


@kernel("float64(float64, float64, float64)")
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


# the gains png_floats reads, in this order (angles in radians)
_PNG_GAINS = ("v_min", "k_a", "a_max", "K_y", "K_z", "tau_zem", "r_mid", "pur_zone", "k_pur",
              "k_brake", "v_max", "fov_margin")  # fmt: skip
_PNG_DEGREES = {"pur_zone", "fov_margin"}
_png_gains_of: tuple[Gains | None, np.ndarray] = (None, np.zeros(len(_PNG_GAINS)))


def _png_gains(gains: Gains) -> np.ndarray:
    """``gains`` as png_floats's array (made again only when the gains object changes)."""
    global _png_gains_of
    held, arr = _png_gains_of
    if held is not gains:
        arr = np.array(
            [
                math.radians(getattr(gains, k)) if k in _PNG_DEGREES else getattr(gains, k)
                for k in _PNG_GAINS
            ]
        )
        _png_gains_of = (gains, arr)
    return arr


def png_law(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    """The proposed law: PNG on the velocity angles plus the k_a speed ramp (eqs. 8-9, 14, 17)."""
    a0, a1, a2, sigma_y, sigma_z, hovering = png_command(
        inp.dt_s, _f3(inp.los_enu), inp.los_elev_rad, inp.d_los_elev_rad, inp.d_los_azim_rad,
        _f3(inp.velocity_enu_m_s), inp.R_WC, inp.fov_edges_rad, inp.range_m,
        inp.target_vel_enu_m_s, inp.target_vel_var_m2_s2, gains, inp.disturbance_enu_m_s2,
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
) -> tuple[float, float, float, float, float, bool]:
    """:func:`png_law` from floats (:class:`GuidanceInput`'s fields, the LOS, the velocity
    and the believed drag and disturbance as three floats each; the loop's tick calls it so):
    (a_d ENU m/s^2 as three floats, sigma_y, sigma_z (nan while hovering), hovering)."""
    e0, e1, e2 = disturbance_enu_m_s2
    l0, l1, l2 = los_enu
    v0, v1, v2 = velocity_enu_m_s
    vt = target_vel_enu_m_s
    t0, t1, t2 = (math.nan,) * 3 if vt is None else _f3(vt)
    top, bottom = fov_edges_rad
    R = R_WC
    a0, a1, a2, sigma_y, sigma_z, hovering = png_floats(
        dt_s, l0, l1, l2, los_elev_rad, d_los_elev_rad, d_los_azim_rad, v0, v1, v2,
        float(R[0, 2]), float(R[1, 2]), float(R[2, 2]), top, bottom, range_m, vt is not None,
        t0, t1, t2, target_vel_var_m2_s2, e0, e1, e2, _png_gains(gains),
    )  # fmt: skip
    if hovering != 0.0:  # the angles are math.nan itself (telemetry compares equal)
        return a0, a1, a2, math.nan, math.nan, True
    return a0, a1, a2, sigma_y, sigma_z, False


@kernel(
    "UniTuple(float64, 6)(float64, float64, float64, float64, float64, float64, float64, "
    "float64, float64, float64, float64, float64, float64, float64, float64, float64, boolean, "
    "float64, float64, float64, float64, float64, float64, float64, float64[::1])"
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
    image's (top, bottom) edges, the DKF's range and target velocity (with its variance),
    the believed drag and disturbance (e0, e1, e2) (:func:`believed_drag_floats`) and the
    gains (``_PNG_GAINS``); returns (a_d, sigma_y, sigma_z, 1 when hovering else 0).

    The speed ramp's tangential acceleration is net of drag: the along-track drag feed-forward
    (:func:`drag_feedforward_floats`) is added after eq. 17's saturation, so that PN keeps its
    whole a_max across the velocity, and before the FOV guard, which sees the whole pitch."""
    v_min, k_a, a_max, K_y, K_z, tau_zem, r_mid = G[0], G[1], G[2], G[3], G[4], G[5], G[6]
    pur_zone, k_pur, k_brake, v_max, fov_margin = G[7], G[8], G[9], G[10], G[11]
    speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if speed < v_min:
        # below v_min the velocity angles are undefined: accelerate along the LOS (§3.4)
        a0, a1, a2 = saturate3(k_a * l0, k_a * l1, k_a * l2, a_max)
        _, a0, a1, a2 = fov_guard_floats(a0, a1, a2, top, ax0, ax1, q_y, fov_margin, a_max)
        return a0, a1, a2, math.nan, math.nan, 1.0
    u0, u1, u2 = v0 / speed, v1 / speed, v2 / speed
    sigma_y, sigma_z = angles_floats(u0, u1, u2)
    # far away PN's LOS-rate term is mostly noise (v/R small): it fades out as the midcourse
    # ZEM-nulling term fades in (README "Range")
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


def track_velocity_direction(
    direction: np.ndarray, v: np.ndarray, speed: float, gains: Gains
) -> np.ndarray:
    """The baselines' velocity loop: a_d = k_v (v_d - v), saturated to a_max, with
    |v_d| = |v| + k_a / k_v (capped at v_max) so that, once aligned, the tangential
    acceleration is k_a as in the proposed law's speed ramp (eq. 14).

    The proposed law's eq. 17 divides by the tick (a gain of 1/dt = 100 1/s). That suits PNG,
    whose v_d is v turned by K dq, but a law that asks for whole heading corrections turns it
    into a saturated limit cycle through the attitude lag; no fair baseline flies like that.
    """
    v_d = min(speed + gains.k_a / gains.k_v, gains.v_max) * direction
    return saturate_norm(gains.k_v * (v_d - v), gains.a_max)


def pursuit_law(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    """PG baseline: desired velocity along the LOS (DESIGN §5)."""
    v = inp.velocity_enu_m_s
    speed = math.sqrt(float(v @ v))
    if speed < gains.v_min:
        return _hover_start(inp, gains)
    sigma_y, sigma_z = direction_angles(v / speed)
    a_d = track_velocity_direction(inp.los_enu, v, speed, gains)
    return GuidanceOutput(a_d, sigma_y, sigma_z, False)


def ibvs_law(inp: GuidanceInput, gains: Gains) -> GuidanceOutput:
    """IBVS baseline, the authors' earlier approach (DESIGN §5): fly along the optical axis
    and drive the image error to zero with the translational part of L_s (eq. 4).

    With camera-frame velocity v_c = v_z ((1 + k) e_x, (1 + k) e_y, 1), eq. 4 gives
    de/dt = -k e v_z / Z: the image error decays as the range closes. Velocity loop as PG.
    """
    v = inp.velocity_enu_m_s
    speed = math.sqrt(float(v @ v))
    if speed < gains.v_min:
        return _hover_start(inp, gains)
    sigma_y, sigma_z = direction_angles(v / speed)
    g = 1.0 + gains.k_ibvs
    d = inp.R_WC @ np.array([g * inp.e_norm[0], g * inp.e_norm[1], 1.0])
    a_d = track_velocity_direction(d / math.sqrt(float(d @ d)), v, speed, gains)
    return GuidanceOutput(a_d, sigma_y, sigma_z, False)


GuidanceLaw = Callable[[GuidanceInput, Gains], GuidanceOutput]

GUIDANCE_LAWS: dict[str, GuidanceLaw] = {
    Law.PNG.value: png_law,
    Law.PG.value: pursuit_law,
    Law.IBVS.value: ibvs_law,
}
assert set(GUIDANCE_LAWS) == {m.value for m in Law}


@kernel("UniTuple(float64, 2)(float64, float64, float64, float64)", uses=(wrap_pi,))
def los_change(
    elev_now: float, azim_now: float, elev_prev: float, azim_prev: float
) -> tuple[float, float]:
    """(dq_y, dq_z) between two ticks, the azimuth difference wrapped to (-pi, pi]."""
    return elev_now - elev_prev, wrap_pi(azim_now - azim_prev)


_LOS_TERMS_SIG = (
    "UniTuple(float64, 12)(float64, float64, float64, float64[:, :], boolean, float64, float64,"
    " float64[:, :], float64, float64, boolean, float64, float64, float64, float64, float64,"
    " float64, float64)"
)


@kernel(_LOS_TERMS_SIG, uses=(wrap_pi,))
def los_terms(
    ex_px: float,
    ey_px: float,
    f_px: float,
    R_WC: np.ndarray,
    has_prev: bool,
    ex_prev_px: float,
    ey_prev_px: float,
    R_WC_prev: np.ndarray,
    dt: float,
    hold: float,
    hold_given: bool,
    tau_los: float,
    filt_y: float,
    filt_z: float,
    flown_y: float,
    flown_z: float,
    flown_hold: float,
    max_late_carry: float,
) -> tuple[float, float, float, float, float, float, float, float, float, float, float, float]:
    """A tick's line-of-sight terms (compiled): the LOS n_t through ``R_WC`` of the image
    estimate (ex, ey) px and its angles (eqs. 5-6), and eq. 8's change (dq_y, dq_z) since the
    previous tick's estimate through ``R_WC_prev`` (with ``has_prev``; else 0).

    ``dt`` is the time since the last tick (s), ``hold`` how long this command is held;
    ``hold_given``: the runtime gave the hold (else it is dt, a fixed grid). With the low-pass
    on (``tau_los`` > 0) the change is filtered as a rate (over dt, per hold) with the state
    (filt_y, filt_z) (nan: none yet); otherwise, given a hold, the part of the last command's
    change (flown_y, flown_z) not flown because it was held dt instead of ``flown_hold`` (nan:
    no last command) is added: the rest when this tick came early, minus the excess (at most
    ``max_late_carry`` holds' worth) when late, so the turn summed over the commands stays K
    times the LOS's. Returns (n_t, q_y, q_z, dq_y, dq_z, filt_y, filt_z, flown_y, flown_z,
    flown_hold), the last five the state for the next tick."""
    n0, n1, n2 = los_floats(ex_px / f_px, ey_px / f_px, R_WC)
    q_y, q_z = angles_floats(n0, n1, n2)
    dq_y = dq_z = 0.0
    if has_prev:
        p0, p1, p2 = los_floats(ex_prev_px / f_px, ey_prev_px / f_px, R_WC_prev)
        qp_y, qp_z = angles_floats(p0, p1, p2)
        dq_y, dq_z = los_change(q_y, q_z, qp_y, qp_z)
        if hold_given and tau_los > 0.0 and hold != dt:
            dq_y *= hold / dt
            dq_z *= hold / dt
    if tau_los > 0.0:
        dq_y = smooth_los_change(filt_y, dq_y, dt, tau_los)
        dq_z = smooth_los_change(filt_z, dq_z, dt, tau_los)
        filt_y, filt_z = dq_y, dq_z
    elif hold_given:
        if not math.isnan(flown_hold) and dt != flown_hold:
            rest = max(1.0 - dt / flown_hold, -max_late_carry)
            dq_y += flown_y * rest
            dq_z += flown_z * rest
        flown_y, flown_z, flown_hold = dq_y, dq_z, hold
    return n0, n1, n2, q_y, q_z, dq_y, dq_z, filt_y, filt_z, flown_y, flown_z, flown_hold
