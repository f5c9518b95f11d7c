"""Delayed Kalman filter (DKF) for the target's image point (DESIGN.md §4).

State x = (e_x, e_y, r_x, r_y): the image error in pixels and the part of its rate that the
camera's rotation does not explain (translation and target motion), in px/s. Prediction adds
the rotational image flow from the gyro (rotational columns of L_s, paper eq. 4); r follows a
white-noise-acceleration model.

Detections arrive late. Every prediction is stored in a ring buffer as (time, gyro, x, P).
A detection captured at t_c is fused at t_c: the filter goes back to the last buffered state
at or before t_c, propagates to t_c with the buffered gyro input, updates, and re-propagates
to now, writing every re-propagated state back into the buffer. Detections that arrive out of
order are fused in capture order by the same replay. The delay comes from timestamps only.
The predict/update algebra is filterpy's.
"""

from __future__ import annotations

import bisect
import enum
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from filterpy.kalman import predict as kf_predict
from filterpy.kalman import update as kf_update

from ..camera_model import CameraModel, rotational_flow
from ..datatypes import Detection

_H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
_B = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0]])
_TIME_EPS_S = 1e-9


@dataclass(frozen=True)
class DkfConfig:
    meas_noise_px: float = 1.5  # detector noise, 1 sigma
    rate_noise_px_s2: float = 100.0  # white-noise acceleration density of r, px/s^2/sqrt(Hz)
    init_rate_std_px_s: float = 150.0
    gate_sigma: float = 5.0  # Mahalanobis gate on the innovation
    lost_timeout_s: float = 0.5  # no accepted detection for this long -> lost
    buffer_s: float = 0.6  # history kept; a detection older than this is rejected

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"DkfConfig.{name} must be a positive number, got {value!r}")


class FusionResult(enum.Enum):
    INITIALISED = "initialised"
    ACCEPTED = "accepted"
    GATED = "gated"  # innovation beyond the Mahalanobis gate
    DUPLICATE = "duplicate"  # same capture time as one already fused
    TOO_OLD = "too_old"  # captured before the oldest buffered state
    FUTURE = "future"  # captured after the filter's current time


@dataclass(frozen=True, slots=True)
class ImageEstimate:
    """The DKF's estimate at ``time_s`` (the time of its last prediction)."""

    time_s: float
    e_px: tuple[float, float]  # image error e = (u - c_u, v - c_v)
    e_rate_px_s: tuple[float, float]  # total rate: rotational flow + r
    e_std_px: tuple[float, float]
    time_since_detection_s: float
    lost: bool


class _Entry:
    __slots__ = ("P", "omega_cam", "t", "x")

    def __init__(self, t: float, omega_cam: np.ndarray, x, P) -> None:
        self.t = t
        self.omega_cam = omega_cam  # camera-frame rate held over (previous entry, t]
        self.x = x
        self.P = P


class DelayedKalmanFilter:
    def __init__(self, camera: CameraModel, config: DkfConfig | None = None) -> None:
        self.camera = camera
        self.config = config or DkfConfig()
        self._R = np.eye(2) * self.config.meas_noise_px**2
        self._gate2 = self.config.gate_sigma**2
        self._max_abs_px = 4.0 * camera.f_px
        self._fq_cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._buf: deque[_Entry] = deque()
        self._meas: list[tuple[float, np.ndarray]] = []  # (capture time, z) in capture order
        self._initialised = False
        self._last_accepted_s = -math.inf
        self.counts: dict[FusionResult, int] = {r: 0 for r in FusionResult}

    # ----------------------------------------------------------------- propagation
    def _transition(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """F and Q for a step of dt seconds (cached: nearly every step is one control period)."""
        key = round(dt, 9)
        cached = self._fq_cache.get(key)
        if cached is not None:
            return cached
        F = np.array(
            [[1.0, 0.0, dt, 0.0], [0.0, 1.0, 0.0, dt], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
        )
        q = self.config.rate_noise_px_s2**2
        q11, q12, q22 = q * dt**3 / 3.0, q * dt**2 / 2.0, q * dt
        Q = np.array(
            [[q11, 0.0, q12, 0.0], [0.0, q11, 0.0, q12], [q12, 0.0, q22, 0.0], [0.0, q12, 0.0, q22]]
        )
        if len(self._fq_cache) < 64:  # replays create odd partial steps; keep it bounded
            self._fq_cache[key] = (F, Q)
        return F, Q

    def _propagate(self, x: np.ndarray, P: np.ndarray, omega_cam: np.ndarray, dt: float):
        if dt <= 0.0:
            return x, P
        f = self.camera.f_px
        fx, fy = rotational_flow(x[0] / f, x[1] / f, omega_cam)
        F, Q = self._transition(dt)
        return kf_predict(x, P, F, Q, np.array([fx * f * dt, fy * f * dt]), _B)

    def predict(self, time_s: float, gyro_rates_flu_rad_s: np.ndarray) -> None:
        """Advance to ``time_s`` with the body rate held since the previous call."""
        omega_cam = self.camera.R_BC.T @ np.asarray(gyro_rates_flu_rad_s, dtype=float)
        if self._buf and time_s <= self._buf[-1].t + _TIME_EPS_S:
            return
        x = P = None
        if self._initialised:
            last = self._buf[-1]
            x, P = self._propagate(last.x, last.P, omega_cam, time_s - last.t)
            if not (abs(x[0]) < self._max_abs_px and abs(x[1]) < self._max_abs_px):
                # predicted far outside the view (> ~76 deg off axis): no longer an estimate
                self._drop_track()
                x = P = None
        self._buf.append(_Entry(time_s, omega_cam, x, P))
        horizon = time_s - self.config.buffer_s
        while len(self._buf) > 2 and self._buf[1].t <= horizon:
            self._buf.popleft()
        # measurements before the oldest buffered state can never be replayed again
        cut = bisect.bisect_left(self._meas, self._buf[0].t, key=lambda m: m[0])
        if cut:
            del self._meas[:cut]

    # ----------------------------------------------------------------- fusion
    @property
    def time_s(self) -> float:
        return self._buf[-1].t if self._buf else -math.inf

    def fuse(self, det: Detection) -> FusionResult:
        """Fuse one detection at its capture time; returns what happened to it."""
        result = self._fuse(det)
        self.counts[result] += 1
        return result

    def _fuse(self, det: Detection) -> FusionResult:
        t_c = det.capture_time_s
        if not self._buf or t_c > self._buf[-1].t + _TIME_EPS_S:
            return FusionResult.FUTURE
        if t_c < self._buf[0].t - _TIME_EPS_S:
            return FusionResult.TOO_OLD
        z = np.array(self.camera.error_px(*det.center_px))
        if not np.all(np.isfinite(z)):
            return FusionResult.GATED
        if any(abs(t - t_c) < _TIME_EPS_S for t, _ in self._meas):
            return FusionResult.DUPLICATE
        now = self._buf[-1].t
        if not self._initialised or now - self._last_accepted_s > self.config.lost_timeout_s:
            return self._initialise(t_c, z)
        # replay from the last buffered state strictly before t_c: an entry at exactly t_c
        # must come out of the replay with this measurement applied
        j = self._index_at_or_before(t_c - 2.0 * _TIME_EPS_S)
        if self._buf[j].t >= t_c - _TIME_EPS_S or self._buf[j].x is None:
            return FusionResult.TOO_OLD
        bisect.insort(self._meas, (t_c, z), key=lambda m: m[0])
        accepted = self._replay(j, self._buf[j].x, self._buf[j].P, self._buf[j].t, t_c)
        return FusionResult.ACCEPTED if accepted else FusionResult.GATED

    def _index_at_or_before(self, t: float) -> int:
        times = [e.t for e in self._buf]
        return max(bisect.bisect_right(times, t + _TIME_EPS_S) - 1, 0)

    def _drop_track(self) -> None:
        for e in self._buf:
            e.x = e.P = None
        self._meas = []
        self._initialised = False

    def _initialise(self, t_c: float, z: np.ndarray) -> FusionResult:
        self._drop_track()
        self._meas = [(t_c, z)]
        s_r = self.config.init_rate_std_px_s
        x0 = np.array([z[0], z[1], 0.0, 0.0])
        P0 = np.diag([self.config.meas_noise_px**2] * 2 + [s_r**2] * 2)
        j = self._index_at_or_before(t_c)
        if abs(self._buf[j].t - t_c) < _TIME_EPS_S:
            self._buf[j].x, self._buf[j].P = x0, P0
        self._initialised = True
        self._last_accepted_s = t_c
        # the state at t_c is the measurement itself; replay forward from there
        self._replay(j, x0, P0, t_c, None)
        return FusionResult.INITIALISED

    def _replay(self, j: int, x, P, t: float, new_t_c: float | None) -> bool:
        """From state (x, P) at time t inside buffer interval j, re-run every later buffered
        step, fusing stored measurements after t in capture order. Writes states back."""
        new_accepted = False
        k = bisect.bisect_right(self._meas, t + _TIME_EPS_S, key=lambda m: m[0])
        buf = self._buf
        for i in range(j + 1, len(buf)):
            entry = buf[i]
            while k < len(self._meas) and self._meas[k][0] <= entry.t + _TIME_EPS_S:
                t_m, z = self._meas[k]
                x, P = self._propagate(x, P, entry.omega_cam, t_m - t)
                t = t_m
                x, P, ok = self._update(x, P, z)
                if ok:
                    self._last_accepted_s = max(self._last_accepted_s, t_m)
                if t_m == new_t_c:
                    new_accepted = ok
                k += 1
            x, P = self._propagate(x, P, entry.omega_cam, entry.t - t)
            t = entry.t
            entry.x, entry.P = x, P
        return new_accepted

    def _update(self, x, P, z):
        y = z - x[:2]
        S = P[:2, :2] + self._R
        d2 = float(y @ np.linalg.solve(S, y))
        if d2 > self._gate2:
            return x, P, False
        x, P = kf_update(x, P, z, self._R, _H)
        return x, P, True

    # ----------------------------------------------------------------- outputs
    def lost(self, now_s: float | None = None) -> bool:
        now = self.time_s if now_s is None else now_s
        return (not self._initialised) or (now - self._last_accepted_s > self.config.lost_timeout_s)

    def estimate(self) -> ImageEstimate | None:
        """Current estimate (at the last prediction time), or None before the first detection."""
        if not self._initialised or not self._buf or self._buf[-1].x is None:
            return None
        e = self._buf[-1]
        f = self.camera.f_px
        fx, fy = rotational_flow(e.x[0] / f, e.x[1] / f, e.omega_cam)
        since = e.t - self._last_accepted_s
        return ImageEstimate(
            time_s=e.t,
            e_px=(float(e.x[0]), float(e.x[1])),
            e_rate_px_s=(float(e.x[2] + fx * f), float(e.x[3] + fy * f)),
            e_std_px=(math.sqrt(e.P[0, 0]), math.sqrt(e.P[1, 1])),
            time_since_detection_s=since,
            lost=since > self.config.lost_timeout_s,
        )

    def state_vector(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Current state (e_x, e_y, r_x, r_y) and the diagonal of its covariance, if any."""
        if not self._initialised or not self._buf or self._buf[-1].x is None:
            return None
        e = self._buf[-1]
        return e.x.copy(), e.P.diagonal().copy()

    def e_px_at(self, time_s: float) -> tuple[float, float] | None:
        """The buffered (replay-corrected) image error at a past prediction time, if held."""
        for e in reversed(self._buf):
            if abs(e.t - time_s) < _TIME_EPS_S:
                return None if e.x is None else (float(e.x[0]), float(e.x[1]))
            if e.t < time_s:
                break
        return None
