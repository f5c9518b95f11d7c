"""Delayed Kalman filter (DKF) for the target's image point, depth and velocity (DESIGN.md §4).

State (normalised image coordinates, internal)::

    x = (x_n, y_n, rho, v_tE, v_tN, v_tU)

x_n = X/Z, y_n = Y/Z the target's normalised image point (pixels / f_px; paper eq. 3), rho = 1/Z
the inverse depth along the optical axis (1/m), v_t the target's velocity in ENU (m/s). It is
the authors' 8-state idea (relative position, relative velocity, image point) written in
inverse-depth form, so the image point stays a state the detector measures directly and the
target's velocity is a world-frame random walk: a static target is v_t = 0, a moving one is
whatever the image flow says it is.

Process (one control step dt, inputs held over the step: gyro omega_c in the camera frame,
vehicle velocity v_c in ENU, camera attitude R_WC). With s = (x_n, y_n, 1) = rho p_c and
u = R_WC^T (v_t - v_c) the target's velocity relative to the camera, in the camera frame::

    s' = s + dt (rho u - omega_c x s),   x_n' = s'_x / s'_z,  y_n' = s'_y / s'_z,  rho' = rho / s'_z

which is exact for the translation over the step (Cartesian Euler of a constant velocity) and
first order in the rotation; its image-point rate is the full interaction matrix L_s (paper
eq. 4): the rotational columns times omega_c plus the translational columns times u with
depth 1/rho. F is the exact Jacobian of that map. v_t is a random walk
(``target_accel_noise_m_s2``); small white noise on the image rate and on rho covers the
unmodelled (camera offset from the centre of mass, gyro noise).

Measurements: the image point (1.5 px), and, when the detection's blob is whole (not touching
the frame edge), its apparent radius r = sqrt(area / pi) ~ f R rho / sqrt(1 + x_n^2 + y_n^2 -
R^2 rho^2) for a sphere of known diameter 2R (``target_diameter_m``), with a loose relative
noise that covers a wrong diameter. The apparent size makes depth observable at once; the
vehicle's own acceleration along and across the line of sight makes it observable over time.
Without size the depth starts from ``init_range_m`` with a wide prior.

Delay: every prediction is buffered as (time, inputs, x, F, Q) and, lazily, P. A detection
captured at t_c is fused at t_c: the filter takes the buffered state just before t_c,
propagates to t_c with the buffered inputs, updates (Joseph form in closed form, equal to
filterpy's ``update``), propagates to the next buffered time, and carries the correction of
the state forward to now through the buffered transition matrices: x_k += Phi_k dx with
Phi_k = F_k ... F_{j+2}, one 3x6 product in floats per buffered step (F's last three rows are
the identity). That is the replay of the linearised filter. The covariance is propagated only
when it is needed (the next fusion, the oldest entry leaving the buffer, a caller asking for
it): P_k = F_k P_{k-1} F_k^T + Q_k from the last entry that holds one, with the buffered F and
Q, which equals carrying dP forward as Phi_k dP Phi_k^T; a tick without a fusion does no 6x6
arithmetic, and every P is computed by the same steps whenever it is asked for, so a caller
that reads the covariance every tick (the simulator's recorded frames) flies bit for bit as
one that never does. A detection captured before one already fused (out of order) is fused by a full
replay in capture order (every step re-propagated with the buffered inputs). Every replayed
state is written back. The delay comes from timestamps only.

Robustness: non-finite or out-of-view detections are refused, the point innovation is gated
(Mahalanobis, 2 dof) and the size innovation separately (1 dof), P is symmetrised at every
update, rho is kept in (0, 1/min_depth_m], and the track is dropped when the prediction leaves
the view by more than ~76 degrees or turns non-finite (the state at every step, the
covariance when it is propagated).

Re-started tracks: a detection after the track went stale (``lost_timeout_s``) starts a new
track at its image point, but with ``carry_max_s`` > 0 (the loop's gain ``t_carry``) and the
old track last confirmed less than that long ago, the new one keeps what the old one still
knows: the target velocity with its covariance grown by the random walk over the time without
measurements (P_vv + q_v dt I: exactly what the propagation does to it), and, when the old
track is still propagated and the detection falls inside its grown image gate, the depth and
the depth-velocity covariance too, the detection's apparent size fused into them. A velocity
vaguer than the first-detection prior (``init_target_speed_m_s``) is not carried.
"""

from __future__ import annotations

import bisect
import dataclasses
import enum
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..camera_model import CameraModel
from ..datatypes import Detection

_TIME_EPS_S = 1e-9
_F64 = np.dtype(np.float64)  # the descriptor of ordinary float arrays
_N = 6  # state size
_MAX_ABS_N = 4.0  # |x_n| beyond this (~76 deg off axis): the track has left the view
_MIN_SZ = 0.2  # one step never shrinks the depth by more than 80 %
_F_LOWER = (
    (0.0,) * 3 + (1.0, 0.0, 0.0) + (0.0,) * 4 + (1.0, 0.0) + (0.0,) * 5 + (1.0,)
)  # F rows 3-5


def _floats3(v) -> tuple[float, float, float]:
    """Three floats from a 3-vector (ndarray or sequence)."""
    if type(v) is np.ndarray and v.dtype is _F64 and v.shape == (3,):
        return tuple(v.tolist())
    out = v.tolist() if isinstance(v, np.ndarray) else [float(c) for c in v]
    if len(out) != 3:
        raise ValueError(f"expected 3 numbers, got {len(out)}")
    return (float(out[0]), float(out[1]), float(out[2]))


def _transposed9(m) -> tuple:
    """The transpose of a 3x3 matrix (ndarray or nested sequence) as 9 floats, row-major."""
    if isinstance(m, np.ndarray) and m.shape == (3, 3) and m.dtype == np.float64:
        return tuple(m.T.ravel().tolist())
    a0, a1, a2 = (_floats3(row) for row in _rows3(m))
    return (a0[0], a1[0], a2[0], a0[1], a1[1], a2[1], a0[2], a1[2], a2[2])


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


def _rows3(m) -> list:
    rows = m.tolist() if isinstance(m, np.ndarray) else list(m)
    if len(rows) != 3:
        raise ValueError("expected a 3x3 matrix")
    return rows


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


class _Entry:
    """One buffered prediction: inputs held over (previous entry, t], the state at t (6
    floats), the transition F from the previous entry's state (its first three rows, 18 floats
    row-major; the rest is the identity), the process noise Q's diagonal over the step, and P
    at t once it has been propagated (None until then)."""

    __slots__ = ("F", "P", "Q", "R_CW", "t", "v_c", "w", "x")

    def __init__(self, t: float, w: tuple, v_c: tuple, R_CW: tuple) -> None:
        self.t = t
        self.w = w  # camera-frame angular rate (rad/s), 3 floats
        self.v_c = v_c  # vehicle velocity ENU (m/s), 3 floats
        self.R_CW = R_CW  # world -> camera rotation, 9 floats row-major
        self.x = None
        self.P = None
        self.F = None
        self.Q = None


def _entry_time(e: _Entry) -> float:
    return e.t


def _meas_time(m: _Meas) -> float:
    return m.t


class _Meas:
    __slots__ = ("r_px", "t", "z")

    def __init__(self, t: float, z: np.ndarray, r_px: float | None) -> None:
        self.t = t
        self.z = z  # normalised image point (x_n, y_n)
        self.r_px = r_px  # apparent radius in px, or None when not usable


class DelayedKalmanFilter:
    def __init__(self, camera: CameraModel, config: DkfConfig | None = None) -> None:
        self.camera = camera
        self._f = camera.f_px
        self.config = config or DkfConfig()
        # default inputs for callers that give only the gyro: vehicle still, body = world
        self._R_CW_default = tuple(camera.R_BC.T.ravel().tolist())
        self._R_CB = self._R_CW_default  # body -> camera, the same numbers
        self._buf: deque[_Entry] = deque()
        self._Fm = np.array((0.0,) * 18 + _F_LOWER).reshape(6, 6)  # scratch F for _propagate
        self._meas: list[_Meas] = []  # in capture order
        self._initialised = False
        self._last_accepted_s = -math.inf
        # a re-started track keeps the old one's depth and target velocity if it was last
        # confirmed less than this long ago (s; 0: every track starts afresh)
        self.carry_max_s = 0.0
        # the last dropped track's (time, v_t, P_vv): the velocity it knew when it was dropped
        self._memory: tuple[float, np.ndarray, np.ndarray] | None = None
        self.counts: dict[FusionResult, int] = {r: 0 for r in FusionResult}

    @property
    def config(self) -> DkfConfig:
        return self._config

    @config.setter
    def config(self, config: DkfConfig) -> None:
        self._config = config
        c, f = config, self._f
        self._r_point = (c.meas_noise_px / f) ** 2
        self._gate2_point = c.gate_sigma**2
        self._q_img = (c.flow_noise_px_s / f) ** 2
        self._q_v = c.target_accel_noise_m_s2**2
        self._q_rho_rel = c.depth_noise_rel**2
        self._rho_max = 1.0 / c.min_depth_m
        self._radius_m = 0.5 * c.target_diameter_m

    # ----------------------------------------------------------------- propagation
    def _step_x(self, x: tuple, e: _Entry, dt: float):
        """Propagate x (6 floats) by dt with entry e's inputs: returns (x' as 6 floats, F's
        first three rows, Q's diagonal)."""
        xn, yn, rho, vE, vN, vU = x
        wx, wy, wz = e.w
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = e.R_CW
        dE, dN, dU = vE - e.v_c[0], vN - e.v_c[1], vU - e.v_c[2]
        ux = r00 * dE + r01 * dN + r02 * dU
        uy = r10 * dE + r11 * dN + r12 * dU
        uz = r20 * dE + r21 * dN + r22 * dU
        sx = xn + dt * (rho * ux - wy + wz * yn)
        sy = yn + dt * (rho * uy - wz * xn + wx)
        sz = 1.0 + dt * (rho * uz - wx * yn + wy * xn)
        if sz < _MIN_SZ:
            sz = _MIN_SZ
        iz = 1.0 / sz
        x1, y1, rho1 = sx * iz, sy * iz, min(rho * iz, self._rho_max)
        # exact Jacobian of the map: d(s_i/s_z) = (ds_i - (s_i/s_z) ds_z) / s_z
        a, b = dt * iz, dt * rho * iz
        F = (
            iz - x1 * a * wy, a * (wz + x1 * wx), a * (ux - x1 * uz),
            b * (r00 - x1 * r20), b * (r01 - x1 * r21), b * (r02 - x1 * r22),
            -a * (wz + y1 * wy), iz + y1 * a * wx, a * (uy - y1 * uz),
            b * (r10 - y1 * r20), b * (r11 - y1 * r21), b * (r12 - y1 * r22),
            -rho1 * a * wy, rho1 * a * wx, iz - rho1 * a * uz,
            -rho1 * b * r20, -rho1 * b * r21, -rho1 * b * r22,
        )  # fmt: skip
        qi, qv = self._q_img * dt, self._q_v * dt
        Q = (qi, qi, self._q_rho_rel * rho1 * rho1 * dt, qv, qv, qv)
        return (x1, y1, rho1, vE, vN, vU), F, Q

    def _propagate(self, P: np.ndarray, F: tuple, Q: tuple) -> np.ndarray:
        """F P F^T + Q (symmetric to rounding; symmetrised at every update). F's first three
        rows are written into a 6x6 scratch matrix whose last three rows are fixed (cheaper
        than making the 36-number array each call; the same numbers, the same products)."""
        Fm = self._Fm
        Fm.reshape(36)[:18] = F  # a view each call: a copied filter keeps its own scratch
        P1 = Fm @ P @ Fm.T
        P1.flat[::7] += Q
        return P1

    def _step(self, x: np.ndarray, P: np.ndarray, e: _Entry, dt: float):
        """Propagate (x, P) by dt with entry e's inputs: returns (x', P', F, Q)."""
        x1, F, Q = self._step_x(x, e, dt)
        return x1, self._propagate(P, F, Q), F, Q

    def _covariance(self, i: int) -> np.ndarray | None:
        """P at buffered entry i, propagated from the last entry before it that holds one
        (None without a track; the track is dropped if it turns non-finite)."""
        buf = self._buf
        e = buf[i]
        if e.P is not None or e.x is None:
            return e.P
        k = i
        while k > 0 and buf[k].P is None and buf[k - 1].x is not None:
            k -= 1
        P = buf[k].P
        if P is None:  # no covariance to start from (cannot happen with a track): drop it
            self._drop_track()
            return None
        for n in range(k + 1, i + 1):
            e = buf[n]
            P = self._propagate(P, e.F, e.Q)
            e.P = P
        if not math.isfinite(float(P.trace())):
            self._drop_track()
            return None
        return P

    def predict(
        self,
        time_s: float,
        gyro_rates_flu_rad_s: np.ndarray,
        velocity_enu_m_s: np.ndarray | None = None,
        R_WC: np.ndarray | None = None,
    ) -> None:
        """Advance to ``time_s`` with the body rate, vehicle velocity (ENU) and camera attitude
        (camera -> ENU) held since the previous call. Without velocity and attitude the vehicle
        is taken as still and level, and the target velocity state absorbs its motion."""
        if self._buf and time_s <= self._buf[-1].t + _TIME_EPS_S:
            return
        prev = self._buf[-1] if self._buf else None
        # plain floats from here on: a handful of numpy calls per tick is the filter's cost
        g0, g1, g2 = _floats3(gyro_rates_flu_rad_s)
        c = self._R_CB
        w = (
            c[0] * g0 + c[1] * g1 + c[2] * g2,
            c[3] * g0 + c[4] * g1 + c[5] * g2,
            c[6] * g0 + c[7] * g1 + c[8] * g2,
        )
        v_c = (0.0, 0.0, 0.0) if velocity_enu_m_s is None else _floats3(velocity_enu_m_s)
        R_CW = self._R_CW_default if R_WC is None else _transposed9(R_WC)
        # a non-finite input is not used: hold the previous one (the filter never sees NaN)
        if not math.isfinite(sum(w)):
            w = prev.w if prev is not None else (0.0, 0.0, 0.0)
        if not math.isfinite(sum(v_c)):
            v_c = prev.v_c if prev is not None else (0.0, 0.0, 0.0)
        if not math.isfinite(sum(R_CW)):
            R_CW = prev.R_CW if prev is not None else self._R_CW_default
        entry = _Entry(time_s, w, v_c, R_CW)
        if self._initialised:
            last = self._buf[-1]
            x, F, Q = self._step_x(last.x, entry, time_s - last.t)
            if self._valid(x):
                entry.x, entry.F, entry.Q = x, F, Q
            else:
                self._drop_track()
        buf = self._buf
        buf.append(entry)
        horizon = time_s - self._config.buffer_s
        while len(buf) > 2 and buf[1].t <= horizon:
            if buf[1].P is None and buf[1].x is not None:
                self._covariance(1)  # the oldest entry is where P is propagated from
            buf.popleft()
        # measurements before the oldest buffered state can never be replayed again (they
        # are in capture order: none to cut unless the first one is)
        meas = self._meas
        if meas and meas[0].t < buf[0].t:
            del meas[: bisect.bisect_left(meas, buf[0].t, key=_meas_time)]

    @staticmethod
    def _valid(x: tuple) -> bool:
        """Finite, in front of the camera and within ~76 degrees of the axis (x: 6 floats)."""
        xn, yn, rho, vE, vN, vU = x
        return (
            abs(xn) < _MAX_ABS_N
            and abs(yn) < _MAX_ABS_N
            and rho > 0.0
            and math.isfinite(vE + vN + vU)
        )

    # ----------------------------------------------------------------- fusion
    @property
    def time_s(self) -> float:
        return self._buf[-1].t if self._buf else -math.inf

    def fuse(self, det: Detection) -> FusionResult:
        """Fuse one detection at its capture time; returns what happened to it."""
        result = self._fuse(det)
        self.counts[result] += 1
        return result

    def _measurement(self, det: Detection) -> _Meas | None:
        """The detection as a measurement, or None when it is not finite."""
        cam = self.camera
        try:
            u, v = (float(c) for c in det.center_px)
            t_c = float(det.capture_time_s)
        except (TypeError, ValueError):
            return None
        ex, ey = cam.error_px(u, v)
        if not (math.isfinite(ex) and math.isfinite(ey) and math.isfinite(t_c)):
            return None
        z = np.array([ex / self._f, ey / self._f])
        if not (abs(z[0]) < _MAX_ABS_N and abs(z[1]) < _MAX_ABS_N):
            return None
        r_px = None
        try:
            area = float(det.area_px)
            bx, by, bw, bh = (float(c) for c in det.bbox_px)
        except (TypeError, ValueError):
            area = math.nan
            bx = by = bw = bh = math.nan
        whole = bx > 0.5 and by > 0.5 and bx + bw < cam.width_px - 0.5
        whole = whole and by + bh < cam.height_px - 0.5
        if math.isfinite(area) and area > 0.0 and whole:
            r_px = math.sqrt(area / math.pi)
        return _Meas(t_c, z, r_px)

    def _fuse(self, det: Detection) -> FusionResult:
        t_c = det.capture_time_s
        if not isinstance(t_c, int | float) or not math.isfinite(t_c):
            return FusionResult.GATED
        if not self._buf or t_c > self._buf[-1].t + self.config.future_tolerance_s:
            return FusionResult.FUTURE
        if t_c > self._buf[-1].t:
            t_c = self._buf[-1].t
            det = dataclasses.replace(det, capture_time_s=t_c)
        if t_c < self._buf[0].t - _TIME_EPS_S:
            return FusionResult.TOO_OLD
        m = self._measurement(det)
        if m is None:
            return FusionResult.GATED
        if any(abs(o.t - t_c) < _TIME_EPS_S for o in self._meas):
            return FusionResult.DUPLICATE
        now = self._buf[-1].t
        if not self._initialised or now - self._last_accepted_s > self.config.lost_timeout_s:
            return self._initialise(m)
        # replay from the last buffered state strictly before t_c: an entry at exactly t_c
        # must come out of the replay with this measurement applied
        j = self._index_at_or_before(t_c - 2.0 * _TIME_EPS_S)
        if self._buf[j].t >= t_c - _TIME_EPS_S or self._buf[j].x is None:
            return FusionResult.TOO_OLD
        if self._meas and self._meas[-1].t > t_c:
            # out of order: full replay in capture order from just before t_c
            bisect.insort(self._meas, m, key=lambda o: o.t)
            b = self._buf[j]
            accepted = self._replay(j, b.x, b.P, b.t, t_c)
        else:
            accepted = self._fuse_latest(j, m)
        return FusionResult.ACCEPTED if accepted else FusionResult.GATED

    def _index_at_or_before(self, t: float) -> int:
        return max(bisect.bisect_right(self._buf, t + _TIME_EPS_S, key=_entry_time) - 1, 0)

    def _drop_track(self) -> None:
        if self._initialised:
            # remember the target velocity at the last entry holding a covariance (v_t is a
            # random walk: from there on only its variance grows, by q_v per second)
            for e in reversed(self._buf):
                if e.x is not None and e.P is not None:
                    v, P_vv = np.array(e.x[3:]), e.P[3:, 3:].copy()
                    if math.isfinite(float(v.sum() + P_vv.sum())):
                        self._memory = (e.t, v, P_vv)
                    break
        for e in self._buf:
            e.x = e.P = e.F = e.Q = None
        self._meas = []
        self._initialised = False

    def _carried(self, m: _Meas) -> tuple[tuple, np.ndarray] | None:
        """The state and covariance to restart a track from at m (capture time m.t), keeping
        what the old track still knows (DESIGN.md §4; README "Track loss"), or None when it
        knows nothing useful. The image point is m's. The target velocity is the old track's,
        its covariance grown by the random walk over the time without measurements
        (P_vv + q_v dt I), if no component is vaguer than the first-detection prior. While the
        old track is still propagated and m falls inside its (grown) image gate, its depth
        and the depth-velocity covariance are kept too and m's apparent size is fused into
        them; otherwise the depth restarts from m's size (or the prior) as for a new track."""
        if m.t - self._last_accepted_s > self.carry_max_s:
            return None
        c = self.config
        s_v2 = c.init_target_speed_m_s**2
        buf = self._buf
        j = self._index_at_or_before(m.t)
        x = P = None
        if self._initialised and buf[j].x is not None:
            P = self._covariance(j)
            x = buf[j].x
            if P is not None and m.t > buf[j].t + _TIME_EPS_S and j + 1 < len(buf):
                x, P, _, _ = self._step(x, P, buf[j + 1], m.t - buf[j].t)
            if P is None or not (self._valid(x) and math.isfinite(float(P.trace()))):
                x = P = None
        if P is not None:
            if float(max(P[3, 3], P[4, 4], P[5, 5])) > s_v2:
                return None
            r = self._r_point
            y0, y1 = float(m.z[0] - x[0]), float(m.z[1] - x[1])
            s00, s01, s11 = float(P[0, 0]) + r, float(P[0, 1]), float(P[1, 1]) + r
            det = s00 * s11 - s01 * s01
            d2 = (s11 * y0 * y0 - 2.0 * s01 * y0 * y1 + s00 * y1 * y1) / det if det > 0 else 1e9
            if d2 <= self._gate2_point:
                # m where the old track predicted it: keep depth and velocity with their
                # covariance, reset the image point (variance 1, ~45 deg: uncorrelated) and
                # fuse m into it (the point, then its size against the carried depth)
                x0 = x
                P0 = P.copy()
                P0[:2, :] = 0.0
                P0[:, :2] = 0.0
                P0[0, 0] = P0[1, 1] = 1.0
                x0, P0, ok = self._update(x0, P0, m)
                return (x0, P0) if ok else None
            v, P_vv = x[3:], P[3:, 3:].copy()
        elif self._memory is not None:
            t0, v, P_vv = self._memory
            P_vv = P_vv + np.eye(3) * (self._q_v * max(m.t - t0, 0.0))
            if float(max(np.diag(P_vv))) > s_v2:
                return None
        else:
            return None
        x0, P0 = self._fresh(m)
        x0 = (*x0[:3], *(v.tolist() if isinstance(v, np.ndarray) else v))
        P0[3:, 3:] = P_vv
        return x0, P0

    def _fresh(self, m: _Meas) -> tuple[tuple, np.ndarray]:
        """A new track's state and covariance at m: the image point, the depth from the
        apparent size (or the prior range), the target velocity 0 +- init_target_speed_m_s."""
        c = self.config
        xn, yn = float(m.z[0]), float(m.z[1])
        n2 = 1.0 + xn * xn + yn * yn
        if m.r_px is not None:
            # r = f R rho / sqrt(n2 - R^2 rho^2)  =>  rho = r sqrt(n2) / sqrt(f^2 R^2 + r^2 R^2)
            R = self._radius_m
            rho = m.r_px * math.sqrt(n2) / (R * math.hypot(self._f, m.r_px))
            rel = math.hypot(c.size_noise_rel, c.size_noise_px / m.r_px)
            s_rho = 2.0 * rel * rho
        else:
            rho = math.sqrt(n2) / c.init_range_m
            s_rho = rho
        rho = min(rho, self._rho_max)
        s_n = c.meas_noise_px / self._f
        s_v = c.init_target_speed_m_s
        x0 = (xn, yn, rho, 0.0, 0.0, 0.0)
        P0 = np.diag([s_n**2, s_n**2, s_rho**2, s_v**2, s_v**2, s_v**2])
        return x0, P0

    def _initialise(self, m: _Meas) -> FusionResult:
        carried = self._carried(m) if self.carry_max_s > 0.0 else None
        self._drop_track()
        self._meas = [m]
        x0, P0 = self._fresh(m) if carried is None else carried
        j = self._index_at_or_before(m.t)
        if abs(self._buf[j].t - m.t) < _TIME_EPS_S:
            self._buf[j].x, self._buf[j].P = x0, P0
        self._initialised = True
        self._last_accepted_s = m.t
        # the state at t_c is the measurement itself; replay forward from there
        self._replay(j, x0, P0, m.t, None)
        return FusionResult.INITIALISED

    def _fuse_latest(self, j: int, m: _Meas) -> bool:
        """Fuse m (later than every stored measurement) captured inside buffer interval
        (j, j+1]: exact at j+1, then the linearised correction of the state carried to now;
        the later covariances are propagated when next needed."""
        buf = self._buf
        P_j = self._covariance(j)
        if P_j is None:
            return False
        nxt = buf[j + 1]
        x, P, _, _ = self._step(buf[j].x, P_j, nxt, m.t - buf[j].t)
        x, P, ok = self._update(x, P, m)
        if not ok:
            return False
        self._meas.append(m)
        self._last_accepted_s = max(self._last_accepted_s, m.t)
        x, P, _, _ = self._step(x, P, nxt, nxt.t - m.t)  # F of the full step stays buffered
        (a0, a1, a2, a3, a4, a5), (b0, b1, b2, b3, b4, b5) = x, nxt.x
        d0, d1, d2, d3, d4, d5 = a0 - b0, a1 - b1, a2 - b2, a3 - b3, a4 - b4, a5 - b5
        nxt.x, nxt.P = x, P
        rho_max = self._rho_max
        for k in range(j + 2, len(buf)):
            # dx_k = F_k dx_{k-1}: F's last three rows are the identity
            e = buf[k]
            F = e.F
            d0, d1, d2 = (
                F[0] * d0 + F[1] * d1 + F[2] * d2 + F[3] * d3 + F[4] * d4 + F[5] * d5,
                F[6] * d0 + F[7] * d1 + F[8] * d2 + F[9] * d3 + F[10] * d4 + F[11] * d5,
                F[12] * d0 + F[13] * d1 + F[14] * d2 + F[15] * d3 + F[16] * d4 + F[17] * d5,
            )
            x0, x1, x2, x3, x4, x5 = e.x
            x2 = min(max(x2 + d2, 1e-6), rho_max)
            e.x = (x0 + d0, x1 + d1, x2, x3 + d3, x4 + d4, x5 + d5)
            e.P = None
        if not self._valid(buf[-1].x):
            self._drop_track()
        return True

    def _replay(self, j: int, x, P, t: float, new_t_c: float | None) -> bool:
        """From state (x, P) at time t inside buffer interval j, re-run every later buffered
        step, fusing stored measurements after t in capture order. Writes states back."""
        new_accepted = False
        meas = self._meas
        k = bisect.bisect_right(meas, t + _TIME_EPS_S, key=lambda o: o.t)
        buf = self._buf
        for i in range(j + 1, len(buf)):
            entry = buf[i]
            while k < len(meas) and meas[k].t <= entry.t + _TIME_EPS_S:
                m = meas[k]
                x, P, _, _ = self._step(x, P, entry, m.t - t)
                t = m.t
                x, P, ok = self._update(x, P, m)
                if ok:
                    self._last_accepted_s = max(self._last_accepted_s, m.t)
                if m.t == new_t_c:
                    new_accepted = ok
                k += 1
            x, P, F, Q = self._step(x, P, entry, entry.t - t)
            t = entry.t
            entry.x, entry.P, entry.F, entry.Q = x, P, F, Q
        last = buf[-1]
        if not (self._valid(last.x) and math.isfinite(float(last.P.trace()))):
            self._drop_track()
        return new_accepted

    def _update(self, x: tuple | np.ndarray, P: np.ndarray, m: _Meas):
        """Gated EKF update with the image point, then (sequentially, relinearised at the
        updated state) the apparent radius if usable and within its own gate. Joseph form in
        closed form for the 2-D and the scalar measurement (equal to filterpy's ``update``;
        tested), cheap enough for every replayed fusion. Returns x as 6 floats."""
        r = self._r_point
        y0, y1 = float(m.z[0] - x[0]), float(m.z[1] - x[1])
        s00, s01, s11 = float(P[0, 0]) + r, float(P[0, 1]), float(P[1, 1]) + r
        det = s00 * s11 - s01 * s01
        if not det > 0.0:
            return x, P, False
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        d2 = y0 * (i00 * y0 + i01 * y1) + y1 * (i01 * y0 + i11 * y1)
        if not d2 <= self._gate2_point:
            return x, P, False
        K = P[:, :2] @ np.array((i00, i01, i01, i11)).reshape(2, 2)  # flat: cheaper to make
        x = x + K @ np.array([y0, y1])
        A = P - K @ P[:2, :]  # (I - K H) P
        P = A - A[:, :2] @ K.T + r * (K @ K.T)
        if m.r_px is not None:
            xn, yn, rho = float(x[0]), float(x[1]), float(x[2])
            R, f = self._radius_m, self._f
            n2 = max(1.0 + xn * xn + yn * yn - (R * rho) ** 2, 1e-6)
            d = f * R / (n2 * math.sqrt(n2))
            hs = np.array([-d * rho * xn, -d * rho * yn, d * (n2 + (R * rho) ** 2), 0, 0, 0])
            c = self.config
            var_s = c.size_noise_px**2 + (c.size_noise_rel * m.r_px) ** 2
            ys = m.r_px - f * R * rho / math.sqrt(n2)
            Ph = P @ hs
            ss = float(hs @ Ph) + var_s
            if ys * ys <= self._gate2_point * ss:
                k = Ph / ss
                x = x + k * ys
                A = P - np.outer(k, Ph)
                P = A - np.outer(A @ hs, k) + var_s * np.outer(k, k)
        x[2] = min(max(x[2], 1e-6), self._rho_max)
        return tuple(x.tolist()), 0.5 * (P + P.T), True

    # ----------------------------------------------------------------- outputs
    def lost(self, now_s: float | None = None) -> bool:
        now = self.time_s if now_s is None else now_s
        return (not self._initialised) or (now - self._last_accepted_s > self.config.lost_timeout_s)

    def _flow(self, e: _Entry) -> tuple[tuple[float, float], tuple[float, float]]:
        """Image-point rate at entry e (normalised/s): (rotational, translational)."""
        xn, yn, rho, vE, vN, vU = e.x
        wx, wy, wz = e.w
        r = e.R_CW
        dE, dN, dU = vE - e.v_c[0], vN - e.v_c[1], vU - e.v_c[2]
        ux = r[0] * dE + r[1] * dN + r[2] * dU
        uy = r[3] * dE + r[4] * dN + r[5] * dU
        uz = r[6] * dE + r[7] * dN + r[8] * dU
        rot = (
            xn * yn * wx - (1.0 + xn * xn) * wy + yn * wz,
            (1.0 + yn * yn) * wx - xn * yn * wy - xn * wz,
        )
        return rot, (rho * (ux - xn * uz), rho * (uy - yn * uz))

    def estimate(self) -> ImageEstimate | None:
        """Current estimate (at the last prediction time), or None before the first detection."""
        if not self._initialised or not self._buf or self._buf[-1].x is None:
            return None
        e = self._buf[-1]
        f = self._f
        rot, tr = self._flow(e)
        since = e.t - self._last_accepted_s
        return ImageEstimate(
            time_s=e.t,
            e_px=(float(e.x[0]) * f, float(e.x[1]) * f),
            e_rate_px_s=((rot[0] + tr[0]) * f, (rot[1] + tr[1]) * f),
            time_since_detection_s=since,
            lost=since > self.config.lost_timeout_s,
        )

    def state_vector(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The current estimate as (e_x, e_y, r_x, r_y) in px and px/s, r being the image rate
        the camera's rotation does not explain, and the diagonal of its covariance (r's
        variance through the Jacobian of the translational flow)."""
        if not self._initialised or not self._buf or self._buf[-1].x is None:
            return None
        if self._covariance(len(self._buf) - 1) is None:
            return None
        e = self._buf[-1]
        f = self._f
        _, tr = self._flow(e)
        # in floats (numpy's per-call cost on these small arrays is most of the work): J is
        # the Jacobian of the translational flow rho (u_xy - s_xy u_z), u = R_CW (v_t - v_c)
        xn, yn, rho, vE, vN, vU = e.x
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = e.R_CW
        dE, dN, dU = vE - e.v_c[0], vN - e.v_c[1], vU - e.v_c[2]
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
        P = e.P.tolist()
        var_r = (_quadratic_form(P, jx), _quadratic_form(P, jy))
        state = np.array([xn * f, yn * f, tr[0] * f, tr[1] * f])
        cov = np.array([P[0][0] * f * f, P[1][1] * f * f, var_r[0] * f * f, var_r[1] * f * f])
        return state, cov

    def range_m(self) -> float | None:
        """Current range along the line of sight (m) from the mean alone (no covariance), or
        None without a track."""
        if not self._initialised or not self._buf or self._buf[-1].x is None:
            return None
        xn, yn, rho = self._buf[-1].x[:3]
        return math.sqrt(1.0 + xn * xn + yn * yn) / rho if rho > 0.0 else math.inf

    def image_std_px(self) -> tuple[float, float] | None:
        """The 1-sigma of the current image point (px, x and y), or None without a track
        (propagates the covariance if it is still lazy)."""
        if not self._initialised or not self._buf or self._buf[-1].x is None:
            return None
        if self._covariance(len(self._buf) - 1) is None:
            return None
        P = self._buf[-1].P
        f = self._f
        return math.sqrt(max(float(P[0, 0]), 0.0)) * f, math.sqrt(max(float(P[1, 1]), 0.0)) * f

    def depth_velocity(self) -> tuple[float, np.ndarray, np.ndarray] | None:
        """Current range along the line of sight (m), the target's velocity (ENU, m/s) and the
        full 6x6 covariance of the internal state, or None without a track."""
        if not self._initialised or not self._buf or self._buf[-1].x is None:
            return None
        if self._covariance(len(self._buf) - 1) is None:
            return None
        e = self._buf[-1]
        xn, yn, rho = e.x[:3]
        return math.sqrt(1.0 + xn * xn + yn * yn) / rho, np.array(e.x[3:]), e.P.copy()

    def e_px_at(self, time_s: float) -> tuple[float, float] | None:
        """The buffered (replay-corrected) image error at a past prediction time, if held."""
        for e in reversed(self._buf):
            if abs(e.t - time_s) < _TIME_EPS_S:
                return None if e.x is None else (float(e.x[0]) * self._f, float(e.x[1]) * self._f)
            if e.t < time_s:
                break
        return None
