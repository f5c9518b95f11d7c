"""Delayed Kalman filter (DKF) for the target's image point, depth and velocity (DESIGN.md §4).

The model (state, process, measurements) and its compiled kernels: :mod:`.dkf_kernels`;
the configuration, results and measurements: :mod:`.dkf_values`. This module holds the
filter: the buffer of predictions, the fusion of delayed detections and the track's life.

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

Re-started tracks: :mod:`.dkf_restart`.
"""

from __future__ import annotations

import bisect
import dataclasses
import math

import numpy as np

from ..camera_model import CameraModel
from ..datatypes import Detection
from .dkf_kernels import (
    _CAPACITY,
    _N,
    _PRM_F,
    _PRM_GATE2,
    _PRM_Q_IMG,
    _PRM_Q_RHO_REL,
    _PRM_Q_V,
    _PRM_R_POINT,
    _PRM_RADIUS,
    _PRM_RHO_MAX,
    _PRM_SIZE_REL,
    _PRM_SIZE_VAR_PX,
    _PRM_TWO,
    _TIME_EPS_S,
    _bisect_right,
    _covariance,
    _fuse_latest,
    _predict,
    _propagate,
    _replay,
    _step_x,
    _update,
    _valid,
    _view,
)
from .dkf_restart import carried_track
from .dkf_values import (
    _NO_INPUT,
    _NO_MATRIX,
    DkfConfig,
    FusionResult,
    ImageEstimate,
    _matrix3,
    _Meas,
    _meas_time,
    _vector3,
    fresh_track,
    image_state,
    measurement,
)

__all__ = ["DelayedKalmanFilter", "DkfConfig", "FusionResult", "ImageEstimate"]


class DelayedKalmanFilter:
    def __init__(self, camera: CameraModel, config: DkfConfig | None = None) -> None:
        self.camera = camera
        self._f = camera.f_px
        self.config = config or DkfConfig()
        # default inputs for callers that give only the gyro: vehicle still, body = world
        self._R_CB = np.ascontiguousarray(camera.R_BC.T.ravel(), dtype=np.float64)
        self._alloc(_CAPACITY)
        self._meas: list[_Meas] = []  # in capture order
        self._initialised = False
        self._last_accepted_s = -math.inf
        # a re-started track keeps the old one's depth and target velocity if it was last
        # confirmed less than this long ago (s; 0: every track starts afresh)
        self.carry_max_s = 0.0
        # the last dropped track's (time, v_t, P_vv): the velocity it knew when it was dropped
        self._memory: tuple[float, np.ndarray, np.ndarray] | None = None
        self.counts: dict[FusionResult, int] = {r: 0 for r in FusionResult}
        self.track_fused = 0  # detections fused into the current track (its first included)

    def _alloc(self, n: int) -> None:
        """The buffer's arrays for n rows (see the buffer layout above), empty."""
        self._T = np.zeros(n)
        self._U = np.zeros((n, 15))
        self._X = np.zeros((n, _N))
        self._F = np.zeros((n, 18))
        self._Q = np.zeros((n, _N))
        self._P = np.zeros((n, _N, _N))
        self._HX = np.zeros(n, dtype=np.uint8)
        self._HP = np.zeros(n, dtype=np.uint8)
        self._win = np.zeros(2, dtype=np.int64)  # the rows in use: [lo, hi)
        self._head_cache: tuple | None = None  # see _head

    @property
    def _lo(self) -> int:
        return int(self._win[0])

    @property
    def _hi(self) -> int:
        return int(self._win[1])

    def _make_room(self) -> None:
        """Free row hi: shift the window to the start of the arrays, or grow them."""
        lo, hi = self._lo, self._hi
        n = hi - lo
        cap = self._T.shape[0]
        arrays = ("_T", "_U", "_X", "_F", "_Q", "_P", "_HX", "_HP")
        if n + 1 > cap // 2:  # grow (to keep the shifts rare)
            old = {a: getattr(self, a) for a in arrays}
            self._alloc(2 * cap)
            for a in arrays:
                getattr(self, a)[:n] = old[a][lo:hi]
        else:
            for a in arrays:
                arr = getattr(self, a)
                arr[:n] = arr[lo:hi]
        self._win[:] = 0, n

    @property
    def config(self) -> DkfConfig:
        return self._config

    @config.setter
    def config(self, config: DkfConfig) -> None:
        self._config = config
        c, f = config, self._f
        self._r_point = (c.meas_noise_px / f) ** 2
        self._gate2_point = c.gate_sigma**2
        self._q_v = c.target_accel_noise_m_s2**2
        self._rho_max = 1.0 / c.min_depth_m
        self._radius_m = 0.5 * c.target_diameter_m
        prm = np.zeros(11)
        prm[_PRM_Q_IMG] = (c.flow_noise_px_s / f) ** 2
        prm[_PRM_Q_V] = self._q_v
        prm[_PRM_Q_RHO_REL] = c.depth_noise_rel**2
        prm[_PRM_RHO_MAX] = self._rho_max
        prm[_PRM_R_POINT] = self._r_point
        prm[_PRM_GATE2] = self._gate2_point
        prm[_PRM_RADIUS] = self._radius_m
        prm[_PRM_F] = f
        prm[_PRM_SIZE_VAR_PX] = c.size_noise_px**2
        prm[_PRM_SIZE_REL] = c.size_noise_rel
        prm[_PRM_TWO] = 2.0
        self._prm = prm

    # ----------------------------------------------------------------- propagation
    def _step(self, x, P: np.ndarray, i: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Propagate (x, P) by dt with buffer row i's inputs: returns (x', P')."""
        x1, F, Q = np.empty(_N), np.empty(18), np.empty(_N)
        _step_x(np.array(x, dtype=np.float64), self._U[i], dt, self._prm, x1, F, Q)
        return x1, _propagate(np.ascontiguousarray(P), F, Q)

    def _covariance(self, i: int) -> np.ndarray | None:
        """P at buffer row i (absolute), propagated from the last row before it that holds
        one (None without a track; the track is dropped if it turns non-finite)."""
        if self._HP[i]:
            return self._P[i]
        code = _covariance(self._P, self._F, self._Q, self._HX, self._HP, self._lo, i)
        if code == 1:
            return self._P[i]
        if code < 0:
            self._drop_track()
        return None

    def predict(
        self,
        time_s: float,
        gyro_rates_flu_rad_s: np.ndarray,
        velocity_enu_m_s: np.ndarray | None = None,
        R_WC: np.ndarray | None = None,
    ) -> None:
        """Advance to ``time_s`` with the body rate, vehicle velocity (ENU) and camera attitude
        (camera -> ENU) held since the previous call. Without velocity and attitude the vehicle
        is taken as still and level, and the target velocity state absorbs its motion. A time
        not after the last prediction, or not finite, changes nothing (a NaN row would stop the
        window from ever trimming; an infinite one would end every later prediction)."""
        lo, hi = self._win.tolist()
        if (hi > lo and time_s <= self._T.item(hi - 1) + _TIME_EPS_S) or not math.isfinite(time_s):
            return
        gyro = _vector3(gyro_rates_flu_rad_s)
        v_c = _NO_INPUT if velocity_enu_m_s is None else _vector3(velocity_enu_m_s)
        R = _NO_MATRIX if R_WC is None else _matrix3(R_WC)
        self._head_cache = None
        if self._initialised and hi > lo and not self._HX[hi - 1]:
            self._drop_track()  # no state to step on (the kernel would step a stale row's)
        if hi == self._T.shape[0]:
            self._make_room()
        T = self._T
        horizon = time_s - self._config.buffer_s
        code = _predict(
            T, self._U, self._X, self._F, self._Q, self._P, self._HX, self._HP, self._win,
            self._initialised, float(time_s), horizon, gyro, v_c, R, self._R_CB, self._prm,
        )  # fmt: skip
        if code < 0:  # the track is lost: drop it, then the rows older than the horizon
            self._drop_track()
            lo, hi = self._win.tolist()
            while hi - lo > 2 and T[lo + 1] <= horizon:
                lo += 1
            self._win[0] = lo
        # measurements before the oldest buffered state can never be replayed again (they
        # are in capture order: none to cut unless the first one is)
        meas = self._meas
        if meas and meas[0].t < T.item(self._win.item(0)):
            lo = self._lo
            del meas[: bisect.bisect_left(meas, T[lo], key=_meas_time)]

    # ----------------------------------------------------------------- fusion
    @property
    def time_s(self) -> float:
        h = self._head()
        return h[1][-1] if h else -math.inf

    def fuse(self, det: Detection) -> FusionResult:
        """Fuse one detection at its capture time; returns what happened to it."""
        result = self._fuse(det)
        self._head_cache = None
        self.counts[result] += 1
        if result is FusionResult.INITIALISED:
            self.track_fused = 1
        elif result is FusionResult.ACCEPTED:
            self.track_fused += 1
        return result

    def _fuse(self, det: Detection) -> FusionResult:
        self._head_cache = None  # the states may change
        t_c = det.capture_time_s
        if not isinstance(t_c, int | float) or not math.isfinite(t_c):
            return FusionResult.GATED
        (lo, hi), T = self._win.tolist(), self._T
        if hi == lo or t_c > T[hi - 1] + self.config.future_tolerance_s:
            return FusionResult.FUTURE
        now = float(T[hi - 1])
        if t_c > now:
            t_c = now
            det = dataclasses.replace(det, capture_time_s=t_c)
        if t_c < T[lo] - _TIME_EPS_S:
            return FusionResult.TOO_OLD
        m = measurement(det, self.camera)
        if m is None:
            return FusionResult.GATED
        if self._duplicate(t_c):
            return FusionResult.DUPLICATE
        if not self._initialised or now - self._last_accepted_s > self.config.lost_timeout_s:
            return self._initialise(m)
        # replay from the last buffered state strictly before t_c: an entry at exactly t_c
        # must come out of the replay with this measurement applied
        j = self._index_at_or_before(t_c - 2.0 * _TIME_EPS_S)
        if T[j] > (t_c - 2.0 * _TIME_EPS_S) + _TIME_EPS_S or not self._HX[j]:
            return FusionResult.TOO_OLD  # (the bound bisect used: no row before t_c)
        if self._meas and self._meas[-1].t > t_c:
            # out of order: full replay in capture order from just before t_c
            bisect.insort(self._meas, m, key=_meas_time)
            P = self._covariance(j)
            accepted = P is not None and self._replay(j, self._X[j], P, float(T[j]), t_c)
            if not accepted and any(o is m for o in self._meas):
                self._meas.remove(m)  # kept only if fused, as in order: no later replay retries it
        else:
            code = _fuse_latest(
                T, self._U, self._X, self._F, self._Q, self._P, self._HX, self._HP,
                self._win, j, m.t, float(m.z[0]), float(m.z[1]),
                math.nan if m.r_px is None else m.r_px, self._prm,
            )  # fmt: skip
            accepted = code == 1
            if code < 0:
                self._drop_track()
            elif accepted:
                self._meas.append(m)
                self._last_accepted_s = max(self._last_accepted_s, m.t)
                if not _valid(self._X[hi - 1]):
                    self._drop_track()
        return FusionResult.ACCEPTED if accepted else FusionResult.GATED

    def _duplicate(self, t_c: float) -> bool:
        """Is a measurement within _TIME_EPS_S of ``t_c`` buffered? (Bisected: they are in
        capture order; the neighbours found are tested as a scan of all would test them.)"""
        meas = self._meas
        i = bisect.bisect_left(meas, t_c - 2.0 * _TIME_EPS_S, key=_meas_time)
        while i < len(meas) and meas[i].t <= t_c + 2.0 * _TIME_EPS_S:
            if abs(meas[i].t - t_c) < _TIME_EPS_S:
                return True
            i += 1
        return False

    def _index_at_or_before(self, t: float) -> int:
        """The buffer row (absolute) of the last prediction at or before t (the oldest if
        none is)."""
        lo, hi = self._win.tolist()
        return max(_bisect_right(self._T, lo, hi, t + _TIME_EPS_S) - 1, lo)

    def _drop_track(self) -> None:
        self._head_cache = None
        lo, hi = self._win.tolist()
        if self._initialised:
            # remember the target velocity at the last entry holding a covariance (v_t is a
            # random walk: from there on only its variance grows, by q_v per second)
            for i in range(hi - 1, lo - 1, -1):
                if self._HX[i] and self._HP[i]:
                    v, P_vv = self._X[i, 3:].copy(), self._P[i, 3:, 3:].copy()
                    if math.isfinite(float(v.sum() + P_vv.sum())):
                        self._memory = (float(self._T[i]), v, P_vv)
                    break
        self._HX[lo:hi] = 0
        self._HP[lo:hi] = 0
        self._meas = []
        self._initialised = False

    def _initialise(self, m: _Meas) -> FusionResult:
        carried = carried_track(self, m) if self.carry_max_s > 0.0 else None
        self._drop_track()
        self._meas = [m]
        x0, P0 = fresh_track(m, self.config, self._f) if carried is None else carried
        x0 = np.array(x0, dtype=np.float64)
        P0 = np.ascontiguousarray(P0, dtype=np.float64)
        j = self._index_at_or_before(m.t)
        # row j is at t_c by the same test that found it (T[j] <= t_c + eps): a stamp a rounding
        # error short of eps before the newest row must still write the new track's state there
        if m.t - _TIME_EPS_S <= self._T[j] <= m.t + _TIME_EPS_S:
            self._X[j], self._P[j] = x0, P0
            self._HX[j] = self._HP[j] = 1
        self._initialised = True
        self._last_accepted_s = m.t
        # the state at t_c is the measurement itself; replay forward from there
        self._replay(j, x0, P0, m.t, None)
        return FusionResult.INITIALISED

    def _replay(self, j: int, x, P, t: float, new_t_c: float | None) -> bool:
        """From state (x, P) at time t inside buffer interval j, re-run every later buffered
        step, fusing stored measurements after t in capture order. Writes states back."""
        meas = self._meas
        k = bisect.bisect_right(meas, t + _TIME_EPS_S, key=_meas_time)
        mt = np.array([o.t for o in meas], dtype=np.float64)
        mz = np.array([o.z for o in meas], dtype=np.float64).reshape(len(meas), 2)
        mr = np.array([math.nan if o.r_px is None else o.r_px for o in meas], dtype=np.float64)
        last = np.array([self._last_accepted_s])
        hi = self._hi
        new_accepted = _replay(
            self._T, self._U, self._X, self._F, self._Q, self._P, self._HX, self._HP, hi, j,
            np.array(x, dtype=np.float64), np.array(P, dtype=np.float64), float(t),
            mt, mz, mr, k, math.nan if new_t_c is None else float(new_t_c), self._prm, last,
        )  # fmt: skip
        self._last_accepted_s = float(last[0])
        if not (self._HX[hi - 1] and self._HP[hi - 1]):
            return new_accepted  # no later entry (j is the newest) and none at j
        if not (_valid(self._X[hi - 1]) and math.isfinite(float(self._P[hi - 1].trace()))):
            self._drop_track()
        return new_accepted

    def _update(self, x, P: np.ndarray, m: _Meas) -> tuple[tuple, np.ndarray, bool]:
        """Gated EKF update of (x, P) with m (the kernel :func:`_update`): returns x as 6
        floats, P and whether it was accepted (x and P unchanged when not)."""
        x_out, P_out = np.empty(_N), np.empty((_N, _N))
        x = np.array(x, dtype=np.float64)
        r_px = math.nan if m.r_px is None else float(m.r_px)
        ok = _update(
            x, np.ascontiguousarray(P, dtype=np.float64), float(m.z[0]), float(m.z[1]), r_px,
            self._prm, x_out, P_out,
        )  # fmt: skip
        if not ok:
            return tuple(x.tolist()), P, False
        return tuple(x_out.tolist()), P_out, True

    # ----------------------------------------------------------------- outputs
    def lost(self, now_s: float | None = None) -> bool:
        now = self.time_s if now_s is None else now_s
        return (not self._initialised) or (now - self._last_accepted_s > self.config.lost_timeout_s)

    def _head(self) -> tuple:
        """The newest rows as Python floats, read once per change of the buffer: (index of
        the newest row, times, state-held flags and states of the newest two rows, the
        newest row's inputs), or () when the buffer is empty."""
        h = self._head_cache
        if h is None:
            lo, hi = self._win.tolist()
            if hi == lo:
                h = ()
            else:
                k = max(hi - 2, lo)
                T, HX, X = self._T[k:hi].tolist(), self._HX[k:hi].tolist(), self._X[k:hi].tolist()
                h = (hi - 1, T, HX, X, self._U[hi - 1].tolist())
            self._head_cache = h
        return h

    def _tracked(self) -> tuple | None:
        """The newest row as (index, time, state, inputs) when it holds a state (a track)."""
        if not self._initialised:
            return None
        h = self._head()
        if not h or not h[2][-1]:
            return None
        return h[0], h[1][-1], h[3][-1], h[4]

    def _read(self, at_s: float | None = None) -> tuple:
        """:func:`_view`'s 14 floats (the estimate, the error at ``at_s``, the range)."""
        return _view(
            self._T, self._U, self._X, self._HX, self._win, self._initialised,
            self._last_accepted_s, self._config.lost_timeout_s, self._f,
            at_s is not None, math.nan if at_s is None else at_s,
        )  # fmt: skip

    def view(
        self, at_s: float | None = None
    ) -> tuple[ImageEstimate | None, tuple[float, float] | None, float | None]:
        """A control tick's reads in one kernel call: :meth:`estimate`, :meth:`e_px_at` of
        ``at_s`` (None without it) and :meth:`range_m`."""
        r = self._read(at_s)
        if r[0] == 0.0:
            est = rng = None
        else:
            est = ImageEstimate(r[1], (r[2], r[3]), (r[4], r[5]), r[6], r[7] != 0.0)
            rng = r[13]
        return est, ((r[11], r[12]) if r[10] != 0.0 else None), rng

    def estimate(self) -> ImageEstimate | None:
        """Current estimate (at the last prediction time), or None before the first detection."""
        return self.view()[0]

    def state_vector(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The current estimate as (e_x, e_y, r_x, r_y) in px and px/s, r being the image rate
        the camera's rotation does not explain, and the diagonal of its covariance (r's
        variance through the Jacobian of the translational flow)."""
        head = self._tracked()
        if head is None or self._covariance(head[0]) is None:
            return None
        i, _, x, u = head
        f = self._f
        tr = self._read()[8:10]  # the translational flow (px/s)
        P = self._P[i].tolist()
        return image_state(x, u, P, f, tr)

    def state_at_capture(self, t_c: float) -> tuple[float, np.ndarray, np.ndarray] | None:
        """The buffered (time s, state, 6x6 covariance) at the first prediction at or after a
        fused detection's capture time ``t_c`` (s): the detection's information and at most one
        step's prediction. None without a track or once the buffer no longer holds ``t_c``."""
        lo, hi = self._win.tolist()
        if not self._initialised or hi == lo or not math.isfinite(t_c):
            return None
        i = _bisect_right(self._T, lo, hi, min(t_c, self._T.item(hi - 1)) - _TIME_EPS_S)
        P = None if i in (hi, lo) or not self._HX[i] else self._covariance(i)
        return None if P is None else (float(self._T[i]), self._X[i].copy(), P.copy())

    def range_m(self) -> float | None:
        """Current range along the line of sight (m) from the mean alone (no covariance), or
        None without a track."""
        return self.view()[2]

    def image_std_px(self) -> tuple[float, float] | None:
        """The 1-sigma of the current image point (px, x and y), or None without a track
        (propagates the covariance if it is still lazy)."""
        head = self._tracked()
        if head is None:
            return None
        P = self._covariance(head[0])
        if P is None:
            return None
        f = self._f
        return math.sqrt(max(float(P[0, 0]), 0.0)) * f, math.sqrt(max(float(P[1, 1]), 0.0)) * f

    def depth_velocity(self) -> tuple[float, np.ndarray, np.ndarray] | None:
        """Current range along the line of sight (m), the target's velocity (ENU, m/s) and the
        full 6x6 covariance of the internal state, or None without a track."""
        head = self._tracked()
        if head is None:
            return None
        P = self._covariance(head[0])
        if P is None:
            return None
        xn, yn, rho = head[2][:3]
        return math.sqrt(1.0 + xn * xn + yn * yn) / rho, np.array(head[2][3:]), P.copy()

    def e_px_at(self, time_s: float) -> tuple[float, float] | None:
        """The buffered (replay-corrected) image error at a past prediction time, if held."""
        return self.view(time_s)[1]
