"""The line of sight from the image and its angles (paper eqs. 5-7), the per-tick LOS change
eq. 8 reads (with its optional low-pass), and the small vector operations every law shares.

All vectors are world ENU.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry import wrap_pi
from ..jit import kernel


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


@kernel("float64(float64, float64, float64, float64)")
def smooth_los_change(prev_rad: float, dq_rad: float, dt_s: float, tau_s: float) -> float:
    """One step of a first-order low-pass on the per-tick LOS change Delta q (eq. 8's input):
    prev + dt / (tau + dt) (dq - prev). Far away the LOS rate |v| sin(angle) / R is small and
    Delta q is mostly image noise; ``tau_s = 0`` passes Delta q through unchanged."""
    if tau_s <= 0.0 or not math.isfinite(prev_rad):
        return dq_rad
    return prev_rad + (dt_s / (tau_s + dt_s)) * (dq_rad - prev_rad)


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
