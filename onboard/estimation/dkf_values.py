"""The delayed Kalman filter's values: its configuration, results, estimate and measurements,
and the pure steps around the kernels (a detection as a measurement, a new track's prior, the
image state's covariance). See :mod:`onboard.estimation.dkf`."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from ..camera_model import CameraModel
from ..datatypes import Detection
from .dkf_kernels import _MAX_ABS_N

_F64 = np.dtype(np.float64)  # the descriptor of ordinary float arrays


def _floats3(v) -> tuple[float, float, float]:
    """Three floats from a 3-vector (ndarray or sequence)."""
    if type(v) is np.ndarray and v.dtype == _F64 and v.shape == (3,):
        return tuple(v.tolist())
    out = v.tolist() if isinstance(v, np.ndarray) else [float(c) for c in v]
    if len(out) != 3:
        raise ValueError(f"expected 3 numbers, got {len(out)}")
    return (float(out[0]), float(out[1]), float(out[2]))


def _vector3(v) -> np.ndarray:
    """A 3-vector (ndarray or sequence) as a writable float64 array (the array itself when it
    is one: the kernels' signatures take writable arrays)."""
    if type(v) is np.ndarray and v.dtype == _F64 and v.shape == (3,) and v.flags.writeable:
        return v
    return np.array(_floats3(v))


def _matrix3(m) -> np.ndarray:
    """A 3x3 matrix (ndarray or nested sequence) as a writable float64 array."""
    if type(m) is np.ndarray and m.dtype == _F64 and m.shape == (3, 3):
        return m if m.flags.writeable else m.copy()
    rows = m.tolist() if isinstance(m, np.ndarray) else list(m)
    if len(rows) != 3:
        raise ValueError("expected a 3x3 matrix")
    return np.array([_floats3(row) for row in rows])


def _quadratic_form(P: list, J: tuple) -> float:
    """J P J^T for a 6x6 matrix P (nested lists) and a row J of 6 floats, skipping J's zeros."""
    out = 0.0
    for j in range(6):
        c = J[j]
        if c:
            row = P[j]
            out += c * (
                row[0] * J[0]
                + row[1] * J[1]
                + row[2] * J[2]
                + row[3] * J[3]
                + row[4] * J[4]
                + row[5] * J[5]
            )
    return out


_NO_INPUT = np.empty(0)  # "not given" for _predict's velocity
_NO_MATRIX = np.empty((0, 0))  # "not given" for _predict's attitude


@dataclass(frozen=True)
class DkfConfig:
    meas_noise_px: float = 1.5  # detector noise on the centre, 1 sigma
    size_noise_px: float = 0.7  # detector noise on the apparent radius, 1 sigma
    size_noise_rel: float = 0.15  # relative error of the radius model (diameter, blob shape)
    target_diameter_m: float = 0.3  # the balloon the detector looks for
    init_range_m: float = 20.0  # depth prior when the first detection has no usable size
    init_target_speed_m_s: float = 3.0  # 1 sigma per ENU axis of the target's first velocity
    target_accel_noise_m_s2: float = 1.0  # random-walk density of v_t, m/s^2 per sqrt(Hz)
    flow_noise_px_s: float = 10.0  # white image-rate model error, px/s per sqrt(Hz)
    depth_noise_rel: float = 0.05  # white relative rate error of rho, 1/sqrt(s)
    min_depth_m: float = 0.1  # rho never exceeds 1 / min_depth_m
    gate_sigma: float = 5.0  # Mahalanobis gate on the point innovation (and on the size's)
    lost_timeout_s: float = 0.5  # no accepted detection for this long -> lost
    buffer_s: float = 0.6  # history kept; a detection older than this is rejected
    # a detection stamped up to this far after the filter's time (camera and IMU clocks a few
    # ms apart; with no camera delay the stamp can lead) is fused at the filter's time
    future_tolerance_s: float = 0.02

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"DkfConfig.{name} must be a positive number, got {value!r}")


class FusionResult(enum.Enum):
    INITIALISED = "initialised"
    ACCEPTED = "accepted"
    GATED = "gated"  # non-finite, or innovation beyond the Mahalanobis gate
    DUPLICATE = "duplicate"  # same capture time as one already fused
    TOO_OLD = "too_old"  # captured before the oldest buffered state
    FUTURE = "future"  # captured after the filter's current time


@dataclass(slots=True)  # not frozen (read-only by convention): a frozen init is 4x dearer
class ImageEstimate:
    """The DKF's estimate at ``time_s`` (the time of its last prediction)."""

    time_s: float
    e_px: tuple[float, float]  # image error e = (u - c_u, v - c_v)
    e_rate_px_s: tuple[float, float]  # total rate: rotational + translational flow
    time_since_detection_s: float
    lost: bool


class _Meas:
    __slots__ = ("r_px", "t", "z")

    def __init__(self, t: float, z: np.ndarray, r_px: float | None) -> None:
        self.t = t
        self.z = z  # normalised image point (x_n, y_n)
        self.r_px = r_px  # apparent radius in px, or None when not usable


def _meas_time(m: _Meas) -> float:
    return m.t


def measurement(det: Detection, camera: CameraModel) -> _Meas | None:
    """The detection as a measurement, or None when it is not finite or out of view."""
    cam = camera
    f = cam.f_px
    try:
        cu, cv = det.center_px
        u, v, t_c = float(cu), float(cv), float(det.capture_time_s)
    except (TypeError, ValueError):
        return None
    ex, ey = cam.error_px(u, v)
    if not (math.isfinite(ex) and math.isfinite(ey) and math.isfinite(t_c)):
        return None
    xn, yn = ex / f, ey / f
    if not (abs(xn) < _MAX_ABS_N and abs(yn) < _MAX_ABS_N):
        return None
    r_px = None
    try:
        area = float(det.area_px)
        bx, by, bw, bh = det.bbox_px
        bx, by, bw, bh = float(bx), float(by), float(bw), float(bh)
    except (TypeError, ValueError):
        area = math.nan
        bx = by = bw = bh = math.nan
    whole = bx > 0.5 and by > 0.5 and bx + bw < cam.width_px - 0.5
    whole = whole and by + bh < cam.height_px - 0.5
    if math.isfinite(area) and area > 0.0 and whole:
        r_px = math.sqrt(area / math.pi)
    return _Meas(t_c, np.array((xn, yn)), r_px)


def fresh_track(m: _Meas, c: DkfConfig, f: float) -> tuple[tuple, np.ndarray]:
    """A new track's state and covariance at m: the image point, the depth from the
    apparent size (or the prior range), the target velocity 0 +- init_target_speed_m_s."""
    xn, yn = float(m.z[0]), float(m.z[1])
    n2 = 1.0 + xn * xn + yn * yn
    if m.r_px is not None:
        # r = f R rho / sqrt(n2 - R^2 rho^2)  =>  rho = r sqrt(n2) / sqrt(f^2 R^2 + r^2 R^2)
        R = 0.5 * c.target_diameter_m
        rho = m.r_px * math.sqrt(n2) / (R * math.hypot(f, m.r_px))
        rel = math.hypot(c.size_noise_rel, c.size_noise_px / m.r_px)
        s_rho = 2.0 * rel * rho
    else:
        rho = math.sqrt(n2) / c.init_range_m
        s_rho = rho
    rho = min(rho, 1.0 / c.min_depth_m)
    s_n = c.meas_noise_px / f
    s_v = c.init_target_speed_m_s
    x0 = (xn, yn, rho, 0.0, 0.0, 0.0)
    P0 = np.diag([s_n**2, s_n**2, s_rho**2, s_v**2, s_v**2, s_v**2])
    return x0, P0


def image_state(x, u, P: list, f: float, tr: tuple) -> tuple[np.ndarray, np.ndarray]:
    """(e_x, e_y, r_x, r_y) in px and px/s from the state x (6), a buffer row's inputs u (15),
    its covariance P (6x6 nested lists), the focal length f (px) and the translational flow tr
    (px/s), and the diagonal of its covariance (r's variance through the Jacobian of the
    translational flow)."""
    # in floats (numpy's per-call cost on these small arrays is most of the work): J is
    # the Jacobian of the translational flow rho (u_xy - s_xy u_z), u = R_CW (v_t - v_c)
    xn, yn, rho, vE, vN, vU = x
    _, _, _, c0, c1, c2, r0, r1, r2, r3, r4, r5, r6, r7, r8 = u
    dE, dN, dU = vE - c0, vN - c1, vU - c2
    u0 = r0 * dE + r1 * dN + r2 * dU
    u1 = r3 * dE + r4 * dN + r5 * dU
    u2 = r6 * dE + r7 * dN + r8 * dU
    a = rho * u2
    jx = (
        -a,
        0.0,
        u0 - xn * u2,
        rho * (r0 - xn * r6),
        rho * (r1 - xn * r7),
        rho * (r2 - xn * r8),
    )
    jy = (
        0.0,
        -a,
        u1 - yn * u2,
        rho * (r3 - yn * r6),
        rho * (r4 - yn * r7),
        rho * (r5 - yn * r8),
    )
    var_r = (_quadratic_form(P, jx), _quadratic_form(P, jy))
    state = np.array([xn * f, yn * f, tr[0], tr[1]])
    cov = np.array([P[0][0] * f * f, P[1][1] * f * f, var_r[0] * f * f, var_r[1] * f * f])
    return state, cov
