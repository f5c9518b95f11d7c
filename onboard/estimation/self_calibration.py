"""In-flight estimates of what the loop cannot know before flight (docs/realism.md
"Self-calibration"): the target's size and the camera's time offset to the IMU.

**Target size from the vehicle's own motion.** A sphere of radius R at range Z shows an
apparent radius r ~ f R / Z, so 1/r is linear in the range. Over the approach the range falls
by the vehicle's own displacement along the line of sight, S(t) = int v_c . n dt, and changes
with the target's own unknown motion along it, w t + a_t t^2 / 2: Z(t) = Z_0 - S(t) + w t +
a_t t^2 / 2, hence

    1 / r = a + b S + c t + d t^2,   b = -1 / (f R),

a weighted least-squares fit (weights r^4 / sigma_r^2, the variance of 1/r) whose slope gives
R without the assumed size. S is only known while the loop has a line of sight: each stretch
of it (a segment) gets its own intercept a. The target's w and a_t have zero-mean priors
(``closing_prior_m_s``, ``closing_accel_prior_m_s2``, turned into priors on c and d with the
believed size). The fit needs the closing speed to change (the speed ramp), else S and t are
collinear and the slope's variance, which the fit reports, stays large. The
estimate is combined with the operator's belief (log-normal, ``prior_rel_std``) so that a poor
fit leaves the belief in charge.

**Camera-IMU time offset from the gyro.** A detection stamped t was captured at t - delta. The
camera's rays turned into a frame carried by the gyro, n_i = R_g(t_i - delta) s_i, are smooth
in time at the true delta (the line of sight moves slowly), while a wrong delta adds the
camera's rotation over the error. The second difference of n over three consecutive frames,
D_i(delta), is therefore noise at the true delta: the estimate minimises
sum |D_i(delta)|^2 / var + delta^2 / prior^2 over a 1 ms grid of candidate offsets (every
frame adds its cost at every candidate; no linearisation, so a start far from the truth does
not bias it), refined by a parabola through the minimum, whose curvature gives the 1 sigma.
It is the offset between the detections' stamps and the gyro's timeline, which is what the
delayed Kalman filter needs (its image-point motion is the gyro's).

Pure maths: no clocks, no I/O. :class:`SelfCalibration` is the loop's adapter over both.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..geometry import rodrigues

_MIN_DT_S = 1e-6


@dataclass(frozen=True)
class SelfCalConfig:
    """Settings of the in-flight estimates (not gains: what the sensors are like)."""

    prior_rel_std: float = 0.3  # the operator's target diameter, relative 1 sigma
    size_noise_px: float = 0.7  # detector noise on the apparent radius, 1 sigma
    size_noise_rel: float = 0.05  # relative noise of the radius (blob shape, 1 sigma)
    min_size_samples: int = 20  # whole blobs before the fit is used
    min_radius_px: float = 3.0  # smaller blobs are left out (1/r skewed, the detector's cut)
    closing_prior_m_s: float = 1.5  # the target's own closing speed before evidence, 1 sigma
    closing_accel_prior_m_s2: float = 1.0  # and its acceleration along the line of sight
    max_size_rel_std: float = 0.5  # a fit vaguer than this is ignored
    offset_prior_std_s: float = 0.02  # camera-IMU offset before any evidence, 1 sigma
    offset_max_s: float = 0.08  # the applied offset never exceeds this
    point_noise_px: float = 1.0  # detector noise on the image point, 1 sigma
    history_s: float = 1.0  # gyro attitudes kept to place a detection
    max_gap_rel: float = 0.25  # three frames used only when their spacings agree this well


@dataclass(frozen=True)
class SelfCalEstimate:
    """The in-flight estimates and their 1-sigma (the operator's belief when no fit)."""

    target_diameter_m: float
    target_diameter_std_m: float
    camera_offset_s: float
    camera_offset_std_s: float
    size_samples: int
    offset_samples: int


class TargetSizeEstimator:
    """Weighted least squares of 1/r = a + b S + c t (module docstring); ``f_px`` the focal
    length, ``believed_diameter_m`` the operator's value (the prior). The weights come from
    the fitted radius, not the measured one (a weight from the noisy radius itself favours
    the blobs measured too large): the fit is iterated twice from the measured radii."""

    def __init__(self, f_px: float, believed_diameter_m: float, config: SelfCalConfig) -> None:
        self.f_px = float(f_px)
        self.config = config
        self.believed_diameter_m = float(believed_diameter_m)
        self._rows: list[tuple[float, float, float, int]] = []  # (t, S, r, segment)
        self._t0: float | None = None

    @property
    def n(self) -> int:
        return len(self._rows)

    def add(self, t_s: float, r_px: float, closing_m: float, segment: int = 0) -> None:
        """One whole blob of apparent radius ``r_px`` captured at ``t_s`` when the vehicle had
        moved ``closing_m`` along the line of sight since the start of ``segment``."""
        if not (r_px >= self.config.min_radius_px and math.isfinite(r_px)):
            return
        if not (math.isfinite(closing_m) and math.isfinite(t_s)):
            return
        if self._t0 is None:
            self._t0 = t_s
        self._rows.append((t_s - self._t0, closing_m, r_px, segment))

    def fit(self) -> tuple[float, float] | None:
        """The fitted diameter (m) and its relative 1 sigma, or None (too few samples, a
        singular or physically wrong fit)."""
        n = self.n
        if n < max(self.config.min_size_samples, 4):
            return None
        c = self.config
        rows = np.array(self._rows)
        segments = np.unique(rows[:, 3])
        if n < len(segments) + 4:
            return None
        tt = rows[:, 0]
        A = np.column_stack((*(rows[:, 3] == k for k in segments), rows[:, 1], tt, tt * tt))
        A = A.astype(float)
        r = rows[:, 2]
        ib, ic, i_d = len(segments), len(segments) + 1, len(segments) + 2  # b, c, d
        y = 1.0 / r
        r_w = r
        # the target's closing speed and acceleration priors as observations of c = w / (f R)
        # and d = a_t / (2 f R), R the believed radius
        fR = self.f_px * 0.5 * self.believed_diameter_m
        c_info = (fR / c.closing_prior_m_s) ** 2
        d_info = (2.0 * fR / c.closing_accel_prior_m_s2) ** 2
        for _ in range(3):
            w = r_w**4 / (c.size_noise_px**2 + (c.size_noise_rel * r_w) ** 2)
            N = A.T @ (w[:, None] * A)
            N[ic, ic] += c_info
            N[i_d, i_d] += d_info
            try:
                cov = np.linalg.inv(N)
            except np.linalg.LinAlgError:
                return None
            theta = cov @ (A.T @ (w * y))
            fitted = A @ theta
            if not np.all(fitted > 0.0):
                break  # keep the last weights
            r_w = 1.0 / fitted
        resid = y - A @ theta
        chi2 = float(w @ (resid * resid)) + c_info * theta[ic] ** 2 + d_info * theta[i_d] ** 2
        scale = max(1.0, chi2 / (n - i_d - 1))  # the residuals, when worse than the noise model
        b = float(theta[ib])
        var_b = float(cov[ib, ib]) * scale
        if not (b < 0.0 and var_b > 0.0 and math.isfinite(var_b)):
            return None
        rel = math.sqrt(var_b) / -b
        if rel > c.max_size_rel_std:
            return None
        return -2.0 / (self.f_px * b), rel

    def estimate(self) -> tuple[float, float]:
        """The diameter (m) from the belief and the fit (combined in log space) and its 1
        sigma (m)."""
        d0, s0 = self.believed_diameter_m, self.config.prior_rel_std
        fit = self.fit()
        if fit is None:
            return d0, d0 * s0
        d1, s1 = fit
        w0, w1 = 1.0 / s0**2, 1.0 / s1**2
        log_d = (w0 * math.log(d0) + w1 * math.log(d1)) / (w0 + w1)
        d = math.exp(log_d)
        return d, d / math.sqrt(w0 + w1)


class CameraOffsetEstimator:
    """The camera-IMU time offset: a cost over a grid of candidate offsets (module
    docstring), fed by :class:`SelfCalibration` with the second differences of its rays."""

    def __init__(self, f_px: float, config: SelfCalConfig) -> None:
        self.config = config
        m = config.offset_max_s
        self.grid_s = np.linspace(-m, m, round(2.0 * m / 0.001) + 1)
        # a second difference of three unit rays with point noise sigma / f each
        self._var_d = 6.0 * (config.point_noise_px / f_px) ** 2
        self._cost = np.zeros(self.grid_s.size)
        self.n = 0

    def add(self, second_difference: np.ndarray) -> None:
        """One sample: the rays' second difference at every candidate offset (grid x 3)."""
        c = np.einsum("ij,ij->i", second_difference, second_difference)
        if np.all(np.isfinite(c)):
            self._cost += c / self._var_d
            self.n += 1

    def estimate(self) -> tuple[float, float]:
        """The offset (s, positive: stamps later than the capture) and its 1 sigma (s), the
        noise taken from the residuals when they are worse than the detector's alone (the
        line of sight's own curvature, the translation's jitter)."""
        prior = self.config.offset_prior_std_s
        if self.n < 10:
            return 0.0, prior
        g = self.grid_s
        k = int(np.argmin(self._cost + (g / prior) ** 2))
        scale = max(1.0, float(self._cost[k]) / (3 * self.n - 1))
        J = self._cost / scale + (g / prior) ** 2
        # a parabola through the candidates within 10 ms of the minimum: between ticks the
        # attitude is interpolated linearly, so the cost has kinks a 3-point stencil would see
        near = np.abs(g - g[k]) <= 0.0105
        c2, c1, _ = np.polyfit(g[near] - g[k], J[near], 2)
        if not c2 > 0.0:
            return float(g[k]), prior
        shift = -c1 / (2.0 * c2)
        return float(g[k] + max(-0.01, min(0.01, shift))), math.sqrt(1.0 / c2)


class SelfCalibration:
    """Both estimates for the loop: call :meth:`on_tick` every control tick,
    :meth:`restamp` on each detection before the DKF and :meth:`on_fused` with each one the
    DKF accepted."""

    def __init__(
        self,
        f_px: float,
        R_BC: np.ndarray,
        believed_diameter_m: float,
        config: SelfCalConfig | None = None,
    ) -> None:
        self.config = config or SelfCalConfig()
        self.f_px = float(f_px)
        self._R_BC = np.array(R_BC, dtype=float)
        self.size = TargetSizeEstimator(f_px, believed_diameter_m, self.config)
        self.offset = CameraOffsetEstimator(f_px, self.config)
        self._R_g = np.eye(3)  # body attitude carried by the gyro (any start)
        self._hist: deque[tuple[float, np.ndarray]] = deque()  # (t, body attitude R_g)
        self._closing: deque[tuple[float, float, int]] = deque()  # (t, S, segment)
        self._S = 0.0
        self._segment = 0  # a new one each time the line of sight comes back
        self._no_los = True
        self._t_prev: float | None = None
        self._queue: deque[tuple[float, np.ndarray]] = deque()  # (stamp, unit ray) to place
        self._frames: deque[tuple[float, np.ndarray]] = deque(maxlen=3)  # (stamp, rays)
        self._offset_est = self.offset.estimate()

    # -------------------------------------------------------------- inputs
    def set_believed_diameter(self, diameter_m: float) -> None:
        self.size.believed_diameter_m = float(diameter_m)

    def on_tick(
        self,
        t_s: float,
        gyro_flu_rad_s: np.ndarray,
        vel_cam_enu_m_s: np.ndarray,
        los_enu: np.ndarray | None,
    ) -> None:
        """Carry the gyro attitude to ``t_s`` (the mean rate since the last tick) and the own
        displacement along the line of sight ``los_enu`` (unit, None: no estimate); place
        the detections whose every candidate capture time is now in the past."""
        if self._t_prev is not None:
            dt = t_s - self._t_prev
            if not dt > 0.0:
                return
            w = np.asarray(gyro_flu_rad_s, dtype=float)
            n = math.sqrt(float(w @ w))
            if n > 0.0 and math.isfinite(n):
                self._R_g = self._R_g @ rodrigues(w / n, n * dt)
            step = math.nan if los_enu is None else float(np.dot(vel_cam_enu_m_s, los_enu)) * dt
            if math.isfinite(step):
                if self._no_los:  # S is unknown across the gap: a new segment
                    self._segment += 1
                    self._no_los = False
                self._S += step
            else:
                self._no_los = True
        self._t_prev = t_s
        self._hist.append((t_s, self._R_g))
        self._closing.append((t_s, math.nan if self._no_los else self._S, self._segment))
        horizon = t_s - self.config.history_s
        while len(self._hist) > 2 and self._hist[1][0] <= horizon:
            self._hist.popleft()
            self._closing.popleft()
        ready = t_s - self.config.offset_max_s
        while self._queue and self._queue[0][0] <= ready:
            self._place(*self._queue.popleft())

    def applied_offset_s(self) -> float:
        """The offset taken off detection stamps: the estimate (within the candidates)."""
        return self._offset_est[0]

    def restamp(self, capture_time_s: float) -> float:
        """A detection's capture time on the gyro's timeline."""
        return capture_time_s - self.applied_offset_s()

    def on_fused(self, stamp_s: float, e_norm: tuple[float, float], r_px: float | None) -> None:
        """A detection the DKF accepted: its stamp as the camera gave it (s), its normalised
        image point (x_n, y_n) and its apparent radius when the blob is whole."""
        if r_px is not None:
            t = stamp_s - self.applied_offset_s()
            at = self._closing_at(t)
            if at is not None:
                self.size.add(t, r_px, *at)
        if self._queue and stamp_s <= self._queue[-1][0] + _MIN_DT_S:
            return  # out of order or repeated: the differences need increasing stamps
        s = np.array((e_norm[0], e_norm[1], 1.0))
        self._queue.append((stamp_s, s / math.sqrt(float(s @ s))))

    # -------------------------------------------------------------- outputs
    def estimate(self) -> SelfCalEstimate:
        d, sd = self.size.estimate()
        o, so = self._offset_est
        return SelfCalEstimate(d, sd, o, so, self.size.n, self.offset.n)

    # -------------------------------------------------------------- helpers
    def _place(self, stamp_s: float, ray: np.ndarray) -> None:
        """The ray turned into the gyro's frame at every candidate capture time; with the two
        frames before it (evenly spaced), one sample of the offset's cost."""
        rays = self._rays(stamp_s - self.offset.grid_s, ray)
        frames = self._frames
        if rays is None:
            frames.clear()
            return
        if frames and stamp_s <= frames[-1][0]:
            return
        frames.append((stamp_s, rays))
        if len(frames) < 3:
            return
        (t0, n0), (t1, n1), (t2, n2) = frames
        g0, g1 = t1 - t0, t2 - t1
        if abs(g1 - g0) > self.config.max_gap_rel * max(g0, g1):
            return  # a dropped frame between: the second difference would not be one
        self.offset.add(n2 - 2.0 * n1 + n0)
        self._offset_est = self.offset.estimate()

    def _rays(self, times_s: np.ndarray, ray: np.ndarray) -> np.ndarray | None:
        """``ray`` turned by the gyro attitude at each of ``times_s`` (linear between ticks),
        or None when a time is outside the history."""
        hist = self._hist
        if len(hist) < 2:
            return None
        t_lo = times_s.min()
        if t_lo < hist[0][0] or times_s.max() > hist[-1][0]:
            return None
        # the newest entries from the last at or before the earliest time: a detection is
        # placed as soon as its candidates are in the past, so they are the history's newest
        # tenths of a second, and the brackets below are those of the whole history
        near = []
        for h in reversed(hist):
            near.append(h)
            if h[0] <= t_lo and len(near) >= 2:
                break
        near.reverse()
        T = np.fromiter((h[0] for h in near), float, len(near))
        Rs = np.stack([h[1] for h in near])
        k = np.clip(np.searchsorted(T, times_s, side="right") - 1, 0, len(T) - 2)
        a = (times_s - T[k]) / np.maximum(T[k + 1] - T[k], _MIN_DT_S)
        n = Rs @ (self._R_BC @ ray)  # the camera ray (the mount is fixed) at each entry
        na, nb = n[k], n[k + 1]
        return na + a[:, None] * (nb - na)

    def _closing_at(self, t: float) -> tuple[float, int] | None:
        """The own displacement along the line of sight at ``t`` (linear between ticks of the
        same segment) and its segment, or None (outside the history, no line of sight)."""
        c = self._closing
        if len(c) < 2 or t < c[0][0] or t > c[-1][0]:
            return None
        for k in range(len(c) - 2, -1, -1):
            if c[k][0] <= t:
                (t0, s0, g0), (t1, s1, g1) = c[k], c[k + 1]
                if g0 != g1 or not (math.isfinite(s0) and math.isfinite(s1)):
                    return None
                return s0 + (t - t0) / max(t1 - t0, _MIN_DT_S) * (s1 - s0), g0
        return None
