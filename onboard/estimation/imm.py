"""The target's world motion as a multiple-model estimate (docs/agility.md): an interacting
multiple-model (IMM) filter over three models of how the target moves, fed with the target's
world position that the DKF and the vehicle's own state give at each fused detection.

State x = (p, v, a): position (m), velocity (m/s) and acceleration (m/s^2), world ENU. The
models (Bar-Shalom, Li & Kirubarajan 2001, ch. 6 and 11.7):

- CV, constant velocity: p += v T, a = 0; white acceleration noise (sigma ``q_cv_m_s2``);
- CA, constant acceleration (Wiener acceleration): p += v T + a T^2 / 2, v += a T; white jerk
  noise (sigma ``q_ca_m_s3``);
- CT, coordinated turn: the horizontal acceleration turns with the velocity at the turn rate
  omega = (v x a)_z / |v_h|^2 of the CT model's own estimate (clipped to ``max_turn_rad_s``),
  a_h rotating by omega T, v_h and p_h its exact integrals over the step; the vertical is CA;
  white jerk noise (sigma ``q_ct_m_s3``). A target turning at 1 rad/s turns its acceleration
  by as much, which CA follows a phase behind; CT carries the turn over the step. With omega
  taken from the estimate, the model is linear in the state at each step (the turn rate is
  its linearisation point); at omega = 0 it is CA.

The models mix as filterpy's :class:`~filterpy.kalman.IMMEstimator` mixes them (Kalman
filters with Joseph-form updates; tests/test_imm.py holds the two equal), the three filters
stacked in arrays so that one update is a few batched products, with the Markov switching
matrix of :class:`ImmConfig` (per update, about the camera's 30 Hz). The combined
acceleration is the model-probability weighted one, so a target the filter believes to fly
straight (CV) reports almost none: an unmanoeuvring target gives the guidance no term to
follow. The measurement is the target's position z = p with the covariance from the DKF's
image point and inverse depth (:func:`position_from_image`): good across the line of sight,
poor along it. Pure maths: no clock, no I/O.
"""

from __future__ import annotations

import copy
import math
import sys
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..geometry import propagate_rotation

MODELS = ("cv", "ca", "ct")  # the models, in the order of every probability vector


@dataclass(frozen=True)
class ImmConfig:
    """The IMM's noises, switching and limits (SI units)."""

    q_cv_m_s2: float = 0.3  # CV: white acceleration, 1 sigma
    q_ca_m_s3: float = 4.0  # CA: white jerk, 1 sigma
    q_ct_m_s3: float = 2.0  # CT: white jerk, 1 sigma
    max_turn_rad_s: float = 3.0  # CT's turn rate is clipped to this
    # Markov switching per update (row: from, column: to), CV / CA / CT
    switching: tuple[tuple[float, float, float], ...] = (
        (0.98, 0.01, 0.01),
        (0.02, 0.96, 0.02),
        (0.02, 0.02, 0.96),
    )
    initial_probabilities: tuple[float, float, float] = (0.8, 0.1, 0.1)
    initial_accel_sigma_m_s2: float = 3.0  # the acceleration's 1 sigma at the start
    min_position_sigma_m: float = 0.02  # the measurement's floor per axis
    max_position_sigma_m: float = 50.0  # a measurement poorer than this (RMS per axis) is unused
    max_gap_s: float = 1.0  # a gap longer than this between updates restarts the filter
    # the vehicle's own pose as the measurement sees it (1 sigma), in the frame its velocity
    # and gyro carry (CarriedPose): the integrated velocity error's drift, and the attitude's,
    # which moves the target across the line of sight by the range times the angle (the
    # estimate's own GNSS and magnetometer wander, decimetres and degrees, is not in it)
    pose_position_sigma_m: float = 0.2
    pose_attitude_sigma_deg: float = 0.6
    # the carried frame's velocity error as process noise (the coloured-noise form: a
    # Gauss-Markov error of this sigma and correlation time, whose rate of change is white
    # acceleration of density 2 sigma^2 / tau on every model); 0: off, the pose term above
    # stands for it (docs/agility.md "What the estimate is worth")
    frame_velocity_sigma_m_s: float = 0.0
    frame_velocity_time_s: float = 1.0

    def __post_init__(self) -> None:
        if not (
            math.isfinite(self.frame_velocity_sigma_m_s) and self.frame_velocity_sigma_m_s >= 0
        ):
            raise ValueError(
                f"frame_velocity_sigma_m_s {self.frame_velocity_sigma_m_s} is not >= 0"
            )
        if not (math.isfinite(self.frame_velocity_time_s) and self.frame_velocity_time_s > 0):
            raise ValueError(f"frame_velocity_time_s {self.frame_velocity_time_s} is not > 0")


@dataclass(frozen=True)
class MotionEstimate:
    """The IMM's output after an update: the combined acceleration (m/s^2 ENU) and velocity
    (m/s ENU), the trace of the acceleration's covariance (m^2/s^4) and the model
    probabilities in :data:`MODELS` order, and the CT model's turn rate (rad/s)."""

    time_s: float
    accel_enu_m_s2: tuple[float, float, float]
    velocity_enu_m_s: tuple[float, float, float]
    accel_var_m2_s4: float
    probabilities: tuple[float, float, float] = field(default=(1.0, 0.0, 0.0))
    # the CT model's turn rate (rad/s about +z, + left; :func:`turn_rate_rad_s`)
    turn_rate_rad_s: float = 0.0

    @property
    def speed_m_s(self) -> float:
        return math.hypot(*self.velocity_enu_m_s)


def position_from_image(
    xn: float, yn: float, rho: float, P3: np.ndarray, R_WC: np.ndarray, camera_enu_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The target's world position (m ENU) and its covariance (m^2) from the DKF's normalised
    image point (xn, yn), inverse depth rho (1/m) and their 3x3 covariance ``P3``, the camera's
    attitude ``R_WC`` and position: p = c + R_WC (xn, yn, 1) / rho, the covariance through
    the Jacobian J = R_WC [[1/rho, 0, -xn/rho^2], [0, 1/rho, -yn/rho^2], [0, 0, -1/rho^2]]."""
    ray = np.array((xn, yn, 1.0))
    p = camera_enu_m + R_WC @ (ray / rho)
    J = R_WC @ np.array(
        (
            (1.0 / rho, 0.0, -xn / rho**2),
            (0.0, 1.0 / rho, -yn / rho**2),
            (0.0, 0.0, -1.0 / rho**2),
        )
    )
    return p, J @ P3 @ J.T


class CarriedPose:
    """The vehicle's pose as its own velocity and gyro carry it from where a track starts: the
    frame the IMM places the target in. The state estimate's position (a GNSS fix's
    Gauss-Markov wander) and heading (a magnetometer's) random-walk by centimetres and tenths
    of a degree between frames, which the IMM would read as the target's acceleration; the
    integrated velocity and gyro drift smoothly (a velocity error of 0.1-0.2 m/s, a gyro bias
    of milliradians a second), which a manoeuvre of m/s^2 does not resemble. The frame is
    anchored to the estimate at the start, so it agrees with the world to the estimate's
    error then plus that drift."""

    def __init__(self, history: int = 64) -> None:
        self.time_s = math.nan
        self.position_enu_m: np.ndarray | None = None
        self.R_WB: np.ndarray | None = None
        # the last steps' (time, position, R_WB): where a detection's capture time placed it
        self._history: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=history)

    def reset(self) -> None:
        """Forget the anchor (the next :meth:`step` takes the estimate) and the past steps."""
        self.position_enu_m = self.R_WB = None
        self._history.clear()

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose (position m ENU, R_WB) of the held step at ``t`` (s, within 1 us), or None
        when none is held."""
        for t_k, p, R in reversed(self._history):
            if abs(t_k - t) <= 1e-6:
                return p, R
            if t_k < t:
                return None
        return None

    def step(
        self,
        t: float,
        position_enu_m: np.ndarray,
        velocity_enu_m_s: np.ndarray,
        R_WB: np.ndarray,
        rates_flu_rad_s: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Carry the pose to ``t`` (s) with the velocity (m/s ENU) and body rates (rad/s FLU)
        held since the last step, or anchor it to the estimate (``position_enu_m``,
        ``R_WB``) when there is none; a time that does not advance or an input that is not
        finite leaves it where it is. Returns (position m ENU, R_WB)."""
        v = np.asarray(velocity_enu_m_s, dtype=float)
        w = np.asarray(rates_flu_rad_s, dtype=float)
        dt = t - self.time_s
        if self.position_enu_m is None:
            self.position_enu_m = np.array(position_enu_m, dtype=float)
            self.R_WB = np.array(R_WB, dtype=float)
            self.time_s = t
            self._history.append((t, self.position_enu_m, self.R_WB))
        elif dt > 0.0 and np.isfinite(v).all() and np.isfinite(w).all():
            self.position_enu_m = self.position_enu_m + v * dt
            self.R_WB = propagate_rotation(self.R_WB, w, dt)
            self.time_s = t
            self._history.append((t, self.position_enu_m, self.R_WB))
        return self.position_enu_m, self.R_WB


def pose_covariance_m2(rel_enu_m: np.ndarray, config: ImmConfig) -> np.ndarray:
    """What the vehicle's own pose error adds to the target's placed position (m^2): its
    position's variance on every axis, and its attitude's, (range sigma_att)^2, across the
    line of sight ``rel_enu_m`` (target less camera, m)."""
    r2 = float(rel_enu_m @ rel_enu_m)
    cov = config.pose_position_sigma_m**2 * np.eye(3)
    if r2 > 0.0:
        across = np.eye(3) - np.outer(rel_enu_m, rel_enu_m) / r2
        cov += r2 * math.radians(config.pose_attitude_sigma_deg) ** 2 * across
    return cov


def frame_noise(dt: float, config: ImmConfig) -> np.ndarray:
    """The carried frame's velocity error over a step ``dt`` (s) as process noise (9x9,
    SI): white acceleration of density s = 2 sigma^2 / tau (m^2/s^3) per axis, through
    position and velocity."""
    s = 2.0 * config.frame_velocity_sigma_m_s**2 / config.frame_velocity_time_s
    Q = np.zeros((9, 9))
    Q[0:3, 0:3] = s * dt**3 / 3.0 * np.eye(3)
    Q[0:3, 3:6] = Q[3:6, 0:3] = s * dt**2 / 2.0 * np.eye(3)
    Q[3:6, 3:6] = s * dt * np.eye(3)
    return Q


def _cv_matrices(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    F = np.eye(9)
    F[0:3, 3:6] = dt * np.eye(3)
    F[6:9, 6:9] = 0.0
    Q = np.zeros((9, 9))
    q2 = q * q
    Q[0:3, 0:3] = q2 * dt**4 / 4.0 * np.eye(3)
    Q[0:3, 3:6] = Q[3:6, 0:3] = q2 * dt**3 / 2.0 * np.eye(3)
    Q[3:6, 3:6] = q2 * dt**2 * np.eye(3)
    Q[6:9, 6:9] = 1e-6 * np.eye(3)  # a = 0 (kept invertible)
    return F, Q


def _ca_matrices(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    F = np.eye(9)
    F[0:3, 3:6] = F[3:6, 6:9] = dt * np.eye(3)
    F[0:3, 6:9] = 0.5 * dt * dt * np.eye(3)
    g = np.array((dt**3 / 6.0, dt**2 / 2.0, dt))  # white jerk through (p, v, a)
    Q = np.kron(np.outer(g, g) * q * q, np.eye(3))
    return F, Q


# slower than this (m/s) a target has no heading to turn: its acceleration is all speed change
MIN_TURN_SPEED_M_S = 0.5


def turn_rate_rad_s(
    velocity_enu_m_s: np.ndarray | tuple[float, ...],
    accel_enu_m_s2: np.ndarray | tuple[float, ...],
    max_turn_rad_s: float,
) -> float:
    """The turn rate (rad/s about +z, + left) of a target moving at ``velocity_enu_m_s`` and
    accelerating at ``accel_enu_m_s2``: omega = (v x a)_z / |v_h|^2, clipped to
    +-``max_turn_rad_s``; 0 slower than MIN_TURN_SPEED_M_S horizontally (no heading to turn)."""
    v0, v1 = float(velocity_enu_m_s[0]), float(velocity_enu_m_s[1])
    vh2 = v0 * v0 + v1 * v1
    omega = (
        (v0 * float(accel_enu_m_s2[1]) - v1 * float(accel_enu_m_s2[0])) / vh2
        if vh2 > MIN_TURN_SPEED_M_S**2
        else 0.0
    )
    return min(max(omega, -max_turn_rad_s), max_turn_rad_s)


def turn_displacement(omega_rad_s: float, t_s: float) -> np.ndarray:
    """B2 (2x2, s^2): the horizontal displacement over ``t_s`` of an acceleration a_h that
    turns at ``omega_rad_s`` about +z, beyond the velocity's v t: the double integral of
    Rot(omega t) over [0, t], B2 = [[1 - c, s - wt], [wt - s, 1 - c]] / omega^2 (wt = omega t,
    s, c its sine and cosine); t^2 / 2 I as omega -> 0 (constant acceleration)."""
    wt = omega_rad_s * t_s
    if abs(wt) < 1e-4:  # the series to wt^3: B2 = t^2 (I/2 + (wt/6) J), J the +90 deg turn
        k = t_s * t_s * wt / 6.0
        return np.array(((0.5 * t_s * t_s, -k), (k, 0.5 * t_s * t_s)))
    s, c = math.sin(wt), math.cos(wt)
    return np.array(((1.0 - c, s - wt), (wt - s, 1.0 - c))) / (omega_rad_s * omega_rad_s)


def _ct_matrices(dt: float, q: float, omega: float) -> tuple[np.ndarray, np.ndarray]:
    """CA whose horizontal acceleration turns at ``omega`` (rad/s) about +z over the step:
    a_h' = Rot(omega T) a_h, v_h' = v_h + B1 a_h, p_h' = p_h + v_h T + B2 a_h with B1, B2 the
    integrals of Rot(omega t) once and twice over [0, T] (:func:`turn_displacement`); white
    jerk noise as CA."""
    F, Q = _ca_matrices(dt, q)
    if abs(omega) > 1e-6:
        wt = omega * dt
        s, c = math.sin(wt), math.cos(wt)
        F[6:8, 6:8] = ((c, -s), (s, c))
        F[3:5, 6:8] = np.array(((s, c - 1.0), (1.0 - c, s))) / omega
        F[0:2, 6:8] = turn_displacement(omega, dt)
    return F, Q


class _ImmState:
    """The three filters stacked (model order :data:`MODELS`): states X (3, 9), covariances
    P (3, 9, 9), model probabilities mu, the switching matrix M, and the mixing terms of
    filterpy's IMMEstimator (cbar = mu M, omega_ij = M_ij mu_i / cbar_j) with the combined
    state x and covariance Pc."""

    def __init__(self, X: np.ndarray, P: np.ndarray, mu: np.ndarray, M: np.ndarray) -> None:
        self.X, self.P, self.M = X, P, M
        self.mu = mu / np.sum(mu)
        self._mixing()
        self._combine()

    def _mixing(self) -> None:
        self.cbar = self.mu @ self.M
        self.omega = self.M * self.mu[:, None] / self.cbar[None, :]

    def _combine(self) -> None:
        mu = self.mu
        self.x = mu @ self.X
        Y = self.X - self.x
        self.Pc = np.einsum("i,ijk->jk", mu, Y[:, :, None] * Y[:, None, :] + self.P)

    def predict(self, F: np.ndarray, Q: np.ndarray) -> None:
        """Mix, then x = F x, P = F P F^T + Q per model (F, Q stacked (3, 9, 9))."""
        w = self.omega  # w[j, i]: the weight of filter j in model i's start
        Xm = w.T @ self.X
        D = self.X[None, :, :] - Xm[:, None, :]  # (i, j, 9)
        Pm = np.einsum("ji,ijkl->ikl", w, D[:, :, :, None] * D[:, :, None, :] + self.P[None])
        self.X = np.einsum("ikl,il->ik", F, Xm)
        self.P = F @ Pm @ F.transpose(0, 2, 1) + Q
        self._combine()

    def update(self, z: np.ndarray, R: np.ndarray) -> None:
        """Fuse the position z (covariance R) in every model (H = [I 0 0], Joseph form), weigh
        the models by the likelihood of their innovations (floored at the smallest float)."""
        y = z[None, :] - self.X[:, :3]
        PHT = self.P[:, :, :3]
        S = self.P[:, :3, :3] + R[None]
        SI = np.linalg.inv(S)
        K = PHT @ SI
        self.X = self.X + np.einsum("ikl,il->ik", K, y)
        I_KH = np.broadcast_to(np.eye(9), (3, 9, 9)).copy()
        I_KH[:, :, :3] -= K
        KT = K.transpose(0, 2, 1)
        self.P = I_KH @ self.P @ I_KH.transpose(0, 2, 1) + K @ R[None] @ KT
        _, logdet = np.linalg.slogdet(S)
        maha = np.einsum("ik,ikl,il->i", y, SI, y)
        lik = np.exp(-0.5 * (maha + logdet + 3.0 * math.log(2.0 * math.pi)))
        lik = np.maximum(lik, sys.float_info.min)
        mu = self.cbar * lik
        self.mu = mu / np.sum(mu)
        self._mixing()
        self._combine()


class TargetMotionImm:
    """The IMM over CV, CA and CT (module docstring). Call :meth:`update` with each new
    position measurement; read :attr:`estimate`."""

    def __init__(self, config: ImmConfig | None = None) -> None:
        self.config = config or ImmConfig()
        self._imm: _ImmState | None = None
        self._time_s = math.nan
        self.estimate: MotionEstimate | None = None
        self.pose = CarriedPose()  # the frame its measurements are placed in

    def reset(self) -> None:
        """Forget the track and its frame (a new one starts at the next update)."""
        self._imm = None
        self.estimate = None
        self.pose.reset()

    def _start(self, t: float, p: np.ndarray, R: np.ndarray, v: np.ndarray) -> None:
        cfg = self.config
        x = np.concatenate([p, v, np.zeros(3)])
        P = np.zeros((9, 9))
        P[0:3, 0:3] = R
        P[3:6, 3:6] = 4.0 * np.eye(3)
        P[6:9, 6:9] = cfg.initial_accel_sigma_m_s2**2 * np.eye(3)
        n = len(MODELS)
        self._imm = _ImmState(
            np.tile(x, (n, 1)),
            np.tile(P, (n, 1, 1)),
            np.array(cfg.initial_probabilities, dtype=float),
            np.array(cfg.switching, dtype=float),
        )
        self._time_s = t
        self._publish(t)

    def _publish(self, t: float) -> None:
        imm = self._imm
        x, P = imm.x, imm.Pc
        mu = tuple(float(m) for m in imm.mu)
        self.estimate = MotionEstimate(
            t,
            (float(x[6]), float(x[7]), float(x[8])),
            (float(x[3]), float(x[4]), float(x[5])),
            float(P[6, 6] + P[7, 7] + P[8, 8]),
            (mu[0], mu[1], mu[2]),
            self._turn_rate(),
        )

    def _turn_rate(self) -> float:
        """CT's own turn rate (the combined acceleration is shrunk toward CV's a = 0)."""
        x = self._imm.X[2]
        return turn_rate_rad_s(x[3:6], x[6:9], self.config.max_turn_rad_s)

    def update(
        self,
        t: float,
        position_enu_m: np.ndarray,
        cov_m2: np.ndarray,
        velocity_guess_enu_m_s: np.ndarray | None = None,
        camera_enu_m: np.ndarray | None = None,
    ) -> MotionEstimate | None:
        """Predict to ``t`` (s) and fuse the target's position (m ENU) with covariance
        ``cov_m2`` (3x3, m^2); ``velocity_guess_enu_m_s`` starts a new track's velocity (zero
        without it); with ``camera_enu_m`` (where the camera believes it is) the vehicle's own
        pose uncertainty is added (:func:`pose_covariance_m2`). A measurement that is not
        finite, or poorer than ``max_position_sigma_m``, changes nothing; a time that does not
        advance is ignored; a gap over ``max_gap_s``, a covariance gone singular or a state
        gone non-finite restarts the track. Returns the estimate."""
        p = np.asarray(position_enu_m, dtype=float)
        R = np.asarray(cov_m2, dtype=float)
        if (
            p.shape != (3,)
            or R.shape != (3, 3)
            or not (np.isfinite(p).all() and np.isfinite(R).all())
        ):
            return self.estimate
        floor = self.config.min_position_sigma_m**2
        R = 0.5 * (R + R.T) + floor * np.eye(3)
        if camera_enu_m is not None:
            R = R + pose_covariance_m2(p - np.asarray(camera_enu_m, dtype=float), self.config)
        if np.trace(R) > 3.0 * self.config.max_position_sigma_m**2:
            return self.estimate  # no depth to speak of: nothing to learn of the motion
        v = np.zeros(3) if velocity_guess_enu_m_s is None else np.asarray(velocity_guess_enu_m_s)
        if not np.isfinite(v).all():
            v = np.zeros(3)
        if self._imm is None or t - self._time_s > self.config.max_gap_s:
            self._start(t, p, R, v)
            return self.estimate
        dt = t - self._time_s
        if not dt > 0.0:
            return self.estimate
        try:
            self._predict(dt)
            self._imm.update(p, R)
        except np.linalg.LinAlgError:  # a covariance gone singular: start again from here
            self._start(t, p, R, v)
            return self.estimate
        if not (np.isfinite(self._imm.x).all() and np.isfinite(self._imm.Pc).all()):
            self._start(t, p, R, v)
            return self.estimate
        self._time_s = t
        self._publish(t)
        return self.estimate

    def update_buffered(
        self,
        t: float,
        x: np.ndarray,
        P6: np.ndarray,
        R_BC: np.ndarray,
        offset_b_m: tuple[float, float, float],
    ) -> bool:
        """:meth:`update` with the DKF's buffered state at ``t`` (s; its (xn, yn, rho, target
        velocity) ``x`` and 6x6 covariance ``P6``, DelayedKalmanFilter.state_at_capture),
        the target placed from the carried pose of that time (the camera at ``offset_b_m``
        in the body, attitude R_WB R_BC). Returns whether the pose of ``t`` was held."""
        pose = self.pose.at(t)
        if pose is None:
            return False
        p_b, R_WB = pose
        camera_enu_m = p_b + R_WB @ np.asarray(offset_b_m, dtype=float)
        p, cov = position_from_image(x[0], x[1], x[2], P6[:3, :3], R_WB @ R_BC, camera_enu_m)
        self.update(t, p, cov, x[3:6], camera_enu_m)
        return True

    def predicted(self, t: float) -> MotionEstimate | None:
        """The estimate predicted to ``t`` (s) by the models and their switching, the filter
        unchanged (a time not after its last update gives :attr:`estimate`)."""
        if self._imm is None or not t > self._time_s or t - self._time_s > self.config.max_gap_s:
            return self.estimate
        held, est = self._imm, self.estimate
        self._imm = copy.copy(held)  # predict rebinds the state's arrays, never writes into them
        try:
            self._predict(t - self._time_s)
            self._publish(t)
            out = self.estimate if np.isfinite(self._imm.x).all() else est
        finally:
            self._imm, self.estimate = held, est
        return out

    def _predict(self, dt: float) -> None:
        cfg = self.config
        imm = self._imm
        omega = self._turn_rate()
        models = (
            _cv_matrices(dt, cfg.q_cv_m_s2),
            _ca_matrices(dt, cfg.q_ca_m_s3),
            _ct_matrices(dt, cfg.q_ct_m_s3, omega),
        )
        Q = np.stack([m[1] for m in models])
        if cfg.frame_velocity_sigma_m_s > 0.0:
            Q = Q + frame_noise(dt, cfg)[None]
        imm.predict(np.stack([m[0] for m in models]), Q)
