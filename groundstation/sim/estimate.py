"""The state-estimate model: what the onboard loop is handed instead of the simulator's truth.

A real interceptor never sees its true state. PX4's EKF2 hands the companion computer an
estimate that is noisy, biased, correlated in time and late; the gyro it integrates has a
bias; the camera's time stamps are off by a few milliseconds; the thrust it commands is not
quite the thrust it gets, and later. This module models each of these, seeded and
switchable one by one from the scenario's ``[estimate]`` table (``--set estimate.KEY=...``):

============================  =======  =====================================================
error (key)                   default  model and source
============================  =======  =====================================================
velocity (vel_noise_m_s,      0.05     First-order Gauss-Markov per ENU axis, correlation time
vel_time_constant_s)          m/s, 1 s 1 s. EKF2 fuses velocity (GNSS ``EKF2_GPS_V_NOISE``
                                       0.3 m/s, vision ``EKF2_EVV_NOISE`` 0.1 m/s, at 5-50 Hz)
                                       and its output is smoothed by the output predictor
                                       (``EKF2_TAU_VEL`` 0.25 s); the error left is a few cm/s,
                                       correlated over about a second (the filter's own time
                                       constant), not white at 100 Hz.
position (pos_noise_m,        0.05 m,  Gauss-Markov per axis. Indoors the paper's vehicle fused
pos_time_constant_s)          2 s      OptiTrack (``EKF2_EVP_NOISE`` 0.1 m default, the real
                                       error smaller); the loop does not use position today,
                                       it is modelled so that the recorded estimate is honest.
attitude (att_noise_deg,      0.2 deg, Gauss-Markov small rotation per body axis (about body
heading_noise_deg,            2 s      z: heading_noise_deg, the same process scaled). EKF2's tilt
att_time_constant_s)                   is held by accelerometer/velocity fusion to a few
                                       tenths of a degree (``EKF2_ANGERR_INIT`` 0.1 rad is
                                       the switch-on uncertainty it converges from);
                                       correlated over seconds as its corrections are slow.
lag (lag_s)                   20 ms    Position and velocity are the vehicle ``lag_s`` ago:
                                       the onboard runtime streams LOCAL_POSITION_NED at
                                       100 Hz (up to 10 ms old at a tick, plus the serial
                                       link) and uses it unstamped, as the state at the tick;
                                       the output predictor that propagates EKF2's delayed
                                       fusion horizon to now through a complementary filter
                                       (``EKF2_TAU_VEL``/``EKF2_TAU_POS`` 0.25 s) adds its
                                       tracking error, a lag of a few ms in manoeuvres.
attitude lag (att_lag_s)      10 ms    Attitude and body rates: ATTITUDE_QUATERNION streamed
                                       at 200 Hz (runner.py's STREAM_RATES_HZ, up to 5 ms
                                       old) from an output predictor updated per integrated
                                       IMU sample (``IMU_INTEG_RATE`` 200 Hz, up to 5 ms),
                                       plus ~1 ms on the link. PX4 stamps it with its sample
                                       time and ``onboard run`` carries it to the tick with
                                       the gyro (fc_state.state_at); the simulator hands it
                                       to the loop the same way (Simulation), so the lag
                                       costs only the gyro's error over it.
gyro bias (gyro_bias_rad_s,   3e-3     Turn-on bias per axis N(0, 3e-3 rad/s = 0.17 deg/s):
gyro_bias_walk_rad_s_sqrt_s)  rad/s,   what stays in the raw gyro (HIGHRES_IMU, which the
                              1e-4     onboard runtime reads) after PX4's calibration, from
                              rad/s/   thermal drift of an ICM-42688-class MEMS gyro (the
                              sqrt(s)  Pixhawk 6C's). Plus a random walk; EKF2's process
                                       noise for it, ``EKF2_GYR_B_NOISE`` 1e-3 rad/s^2, is a
                                       deliberately loose upper bound, the sensors' bias
                                       instability (a few deg/h) a lower one. The white gyro
                                       noise stays where it was, ``sim.gyro_noise_rad_s``
                                       (3e-3 rad/s a 10 ms sample; EKF2_GYR_NOISE 1.5e-2 is
                                       again a loose filter setting).
camera-IMU time               5 ms,    Detections are stamped with capture time + an offset
(camera_time_offset_s,        1 ms     drawn once a sortie, N(0, 5 ms), + N(0, 1 ms) each
camera_stamp_jitter_s)                 frame: the stamp is start-of-frame while the target's
                                       rows are read mid-exposure and mid rolling-shutter
                                       readout (milliseconds on a CSI camera), and the
                                       companion-FC clock sync (MAVLink TIMESYNC) is good to
                                       about a millisecond. Camera-IMU calibrations (Kalibr)
                                       of unsynchronised cameras find offsets of this order.
thrust (thrust_scale_sigma)   0.02     True thrust = commanded x s, s ~ N(1, 0.02) once a
                                       sortie (clipped to 3 sigma): the loop's thrust model
                                       (max thrust, hover thrust) is off by the battery's sag
                                       and the hover-thrust estimate's error (PX4's
                                       estimator, ``MPC_USE_HTE``, tracks hover thrust to a
                                       few percent). Saturation is then at s x max thrust,
                                       where the loop does not expect it (s > 1 still clips
                                       at the airframe's max thrust).
command latency               5 ms     The rate/thrust command reaches the actuators this much
(command_delay_s)                      later: MAVLink SET_ATTITUDE_TARGET on a 921600 baud
                                       link, then PX4's offboard and rate-controller
                                       scheduling (gyro-rate, ~1 kHz).
============================  =======  =====================================================

The motor lag itself is already in the airframe (``interceptor.thrust_time_constant_s``
0.03 s: PX4 passes the thrust setpoint straight to the mixer, so the thrust response *is* the
motors' and ESCs'; ``interceptor.rate_time_constant_s`` 0.05 s is PX4's closed rate loop).

Every error has its own random stream (children of the sortie's seed): switching one off
leaves the others' draws unchanged. ``estimate.enabled = false`` hands the loop the truth (the
ideal-sensor figures). Pure maths: time comes in with the samples, no clock is read.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from onboard.datatypes import Detection, VehicleState
from onboard.geometry import carried_attitude, quat_exp3, quat_mul4
from onboard.jit import kernel
from onboard.link.fc_state import MAX_PROPAGATION_RATE_RAD_S, MAX_PROPAGATION_S

from ..scenario import EstimateSpec
from .physics import X_P, gyro_mean
from .random_processes import (
    BLOCK,
    gauss_markov_factors,
    gauss_markov_step,
    random_walk_step,
)

_QUAT = (quat_exp3, quat_mul4)  # the kernels of other files estimate_of calls
_STEPS = (gauss_markov_factors, gauss_markov_step, random_walk_step)  # advance_errors's

# the independent random streams, in spawn order (a new error goes at the end)
STREAMS = ("position", "velocity", "attitude", "gyro_bias", "camera_time", "thrust")


@dataclass(slots=True)  # not frozen (read-only by convention)
class _Sample:
    """One sample of the truth: time, position, velocity, attitude (w, x, y, z) and body rates
    (sequences of floats)."""

    time_s: float
    p: tuple
    v: tuple
    q: tuple
    w: tuple


# a delay line's array: row 0 (first index of the history, samples held, lag in s), then one
# row per sample (time, position, velocity, attitude w x y z, body rates), a ring
_RING_COLS = 14


@kernel("void(f8[:, ::1], f8[::1], f8[::1])")
def delay_push(ring: np.ndarray, now: np.ndarray, out: np.ndarray) -> None:
    """Push the sample ``now`` (time, p, v, q, w: 14 floats) into the delay line ``ring``
    (room for one more) and write into ``out`` the truth ``lag`` before it: linearly
    interpolated between the samples held (the quaternion on the short way, normalised after
    interpolation), the oldest sample while the history does not reach back that far, the
    newest with no lag."""
    cap = ring.shape[0] - 1
    lo, n, lag = int(ring[0, 0]), int(ring[0, 1]), ring[0, 2]
    j = 1 + (lo + n) % cap
    for c in range(_RING_COLS):
        ring[j, c] = now[c]
    n += 1
    tq = now[0] - lag
    tq_eps = tq + 1e-12
    while n >= 2 and ring[1 + (lo + 1) % cap, 0] <= tq_eps:
        lo = (lo + 1) % cap
        n -= 1
    ring[0, 0], ring[0, 1] = lo, n
    a = ring[1 + lo]
    if n == 1 or tq <= a[0] + 1e-12:
        for c in range(_RING_COLS):
            out[c] = a[c]
        return
    b = ring[1 + (lo + 1) % cap]
    f = (tq - a[0]) / (b[0] - a[0])
    out[0] = tq
    for c in (1, 2, 3, 4, 5, 6, 11, 12, 13):  # position, velocity, body rates
        out[c] = a[c] + f * (b[c] - a[c])
    a0, a1, a2, a3 = a[7], a[8], a[9], a[10]
    b0, b1, b2, b3 = b[7], b[8], b[9], b[10]
    if not a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 >= 0.0:
        b0, b1, b2, b3 = -b0, -b1, -b2, -b3
    q0, q1, q2, q3 = (
        a0 + f * (b0 - a0),
        a1 + f * (b1 - a1),
        a2 + f * (b2 - a2),
        a3 + f * (b3 - a3),
    )
    m = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    out[7], out[8], out[9], out[10] = q0 / m, q1 / m, q2 / m, q3 / m


class DelayLine:
    """The truth ``lag_s`` ago (:func:`delay_push`); the history grows as it needs to."""

    def __init__(self, lag_s: float) -> None:
        self.lag_s = float(lag_s)
        self.ring = np.zeros((9, _RING_COLS))
        self.ring[0, 2] = self.lag_s

    def room(self) -> np.ndarray:
        """The ring, with room for one more sample."""
        ring = self.ring
        cap = ring.shape[0] - 1
        n = int(ring[0, 1])
        if n < cap:
            return ring
        lo = int(ring[0, 0])
        grown = np.zeros((2 * cap + 1, _RING_COLS))
        grown[0, 1:] = ring[0, 1:]
        grown[1 : 1 + n] = np.roll(ring[1:], -lo, axis=0)
        self.ring = grown
        return grown

    def push(self, s: _Sample) -> _Sample:
        now = np.array((s.time_s, *s.p, *s.v, *s.q, *s.w), dtype=float)
        out = np.empty(_RING_COLS)
        delay_push(self.room(), now, out)
        t, *o = out.tolist()
        return _Sample(t, tuple(o[0:3]), tuple(o[3:6]), tuple(o[6:10]), tuple(o[10:13]))


# the model's numbers (StateEstimateModel._k): time of the last step (NaN before the first),
# next row of the normals' blocks, the attitude lag (s), the Gauss-Markov processes'
# (position, velocity, attitude) time constants and sigmas, the bias's walk, and the
# runtime's limits on carrying the attitude (fc_state)
K_T, K_ROW, K_ATT_LAG, K_TAU, K_SIGMA, K_WALK, K_MAX_DT, K_MAX_RATE = 0, 1, 2, 3, 6, 9, 10, 11
K_HEADING = 12  # the attitude error about body z over the other axes' (heading / attitude)
K_SIZE = 13
# the error processes' rows (StateEstimateModel._x, ._normals)
E_POS, E_VEL, E_ATT, E_BIAS = 0, 1, 2, 3


@kernel("void(f8, f8[::1], f8[:, ::1], f8[:, :, ::1])", uses=_STEPS)
def advance_errors(t: float, k: np.ndarray, x: np.ndarray, normals: np.ndarray) -> None:
    """Step every error process (rows of ``x``) to ``t`` (s), once per distinct time, each
    with the next row of its own block of normals."""
    last = k[K_T]
    if last == last:  # not before the first
        dt = t - last
        if dt <= 0.0:
            return
        i = int(k[K_ROW])
        for p in range(3):
            a, b = gauss_markov_factors(dt, k[K_TAU + p], k[K_SIGMA + p])
            gauss_markov_step(x[p], a, b, normals[p, i])
        random_walk_step(x[E_BIAS], k[K_WALK] * math.sqrt(dt), normals[E_BIAS, i])
        k[K_ROW] = i + 1
    k[K_T] = t


@kernel("void(f8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1])", uses=_QUAT)
def estimate_of(
    k: np.ndarray,
    x: np.ndarray,
    ring: np.ndarray,
    att_ring: np.ndarray,
    now: np.ndarray,
    out: np.ndarray,
) -> None:
    """The estimate of the truth ``now`` (time, p, v, q, w), the errors stepped to its time:
    into ``out`` position, velocity, attitude (w, x, y, z) and body rates (13 floats), the
    position and velocity ``lag_s`` old, attitude and rates ``att_lag_s`` old."""
    old = np.empty(_RING_COLS)
    delay_push(ring, now, old)
    for c in range(3):
        out[c] = old[1 + c] + x[E_POS, c]
        out[3 + c] = old[4 + c] + x[E_VEL, c]
    delay_push(att_ring, now, old)
    # a unit quaternion times a unit quaternion: no renormalising, so that zero errors hand
    # the loop the truth bit for bit
    e0, e1, e2, e3 = quat_exp3(x[E_ATT, 0], x[E_ATT, 1], x[E_ATT, 2] * k[K_HEADING])
    out[6], out[7], out[8], out[9] = quat_mul4(old[7], old[8], old[9], old[10], e0, e1, e2, e3)
    for c in range(3):
        out[10 + c] = old[11 + c] + x[E_BIAS, c]


@kernel(
    "void(f8, f8[::1], f8, f8, f8, f8, f8[::1], f8[:, ::1], f8[:, :, ::1], f8[:, ::1],"
    " f8[:, ::1], f8[::1])",
    uses=(gyro_mean, carried_attitude, *_QUAT),
)
def hand_off(
    t: float,
    truth: np.ndarray,
    n0: float,
    n1: float,
    n2: float,
    sigma: float,
    k: np.ndarray,
    x: np.ndarray,
    normals: np.ndarray,
    ring: np.ndarray,
    att_ring: np.ndarray,
    out: np.ndarray,
) -> None:
    """A control tick's inputs as ``onboard run`` hands them to the loop, from the vehicle's
    true state ``truth`` (X_* layout) at ``t``: into ``out`` the gyro sample (the mean rate
    since the last tick, its white noise ``sigma`` (n0, n1, n2) and the bias), then the
    estimated position, velocity, attitude and body rates (:func:`estimate_of`), the
    attitude carried to the tick from its stamp ``att_lag_s`` before it with that gyro
    sample (``fc_state.vehicle_state_at``'s :func:`carried_attitude`) and the time it is of
    (17 floats)."""
    r0, r1, r2 = gyro_mean(truth)
    r0, r1, r2 = r0 + n0 * sigma, r1 + n1 * sigma, r2 + n2 * sigma
    advance_errors(t, k, x, normals)
    g0, g1, g2 = r0 + x[E_BIAS, 0], r1 + x[E_BIAS, 1], r2 + x[E_BIAS, 2]
    out[0], out[1], out[2] = g0, g1, g2
    now = np.empty(_RING_COLS)
    now[0] = t
    for c in range(13):  # position, velocity, attitude, body rates: X_P .. X_W + 2
        now[1 + c] = truth[X_P + c]
    est = out[3:16]
    estimate_of(k, x, ring, att_ring, now, est)
    q0, q1, q2, q3, q_at = carried_attitude(
        t, est[6], est[7], est[8], est[9], t - k[K_ATT_LAG], g0, g1, g2, k[K_MAX_DT],
        k[K_MAX_RATE],
    )  # fmt: skip
    est[6], est[7], est[8], est[9] = q0, q1, q2, q3
    out[16] = q_at


class _Error:
    """One error process of the model: :attr:`x` its state now (a view), :attr:`value` a
    copy."""

    def __init__(self, x: np.ndarray) -> None:
        self.x = x

    @property
    def value(self) -> np.ndarray:
        return self.x.copy()


class StateEstimateModel:
    """The errors of one sortie (see the module docstring). Call :meth:`vehicle_state` and
    :meth:`gyro` at each control tick (time non-decreasing), :meth:`stamp` on each delivered
    detection; :attr:`thrust_scale` and :attr:`command_delay_s` shape the actuation. The
    simulator calls :meth:`hand_off` instead of the first two (one kernel call a tick)."""

    def __init__(self, spec: EstimateSpec, seed: np.random.SeedSequence) -> None:
        self.spec = spec
        rngs = dict(
            zip(STREAMS, (np.random.default_rng(s) for s in seed.spawn(len(STREAMS))), strict=True)
        )
        self._rngs = [rngs[name] for name in ("position", "velocity", "attitude", "gyro_bias")]
        self._normals = np.empty((4, BLOCK, 3))
        self._k = k = np.full(K_SIZE, math.nan)
        self._draw()
        k[K_TAU : K_TAU + 3] = (
            spec.pos_time_constant_s,
            spec.vel_time_constant_s,
            spec.att_time_constant_s,
        )
        sigmas = (spec.pos_noise_m, spec.vel_noise_m_s, math.radians(spec.att_noise_deg))
        k[K_SIGMA : K_SIGMA + 3] = sigmas
        k[K_WALK] = spec.gyro_bias_walk_rad_s_sqrt_s
        k[K_ATT_LAG] = spec.att_lag_s
        att = spec.att_noise_deg
        k[K_HEADING] = spec.heading_noise_deg / att if att > 0.0 else 0.0
        k[K_MAX_DT], k[K_MAX_RATE] = MAX_PROPAGATION_S, MAX_PROPAGATION_RATE_RAD_S
        # each process starts in its stationary distribution (the bias at its turn-on sigma)
        self._x = np.empty((4, 3))
        for p, s in enumerate((*sigmas, spec.gyro_bias_rad_s)):
            self._x[p] = float(s) * self._normals[p, 0]
        k[K_ROW] = 1.0
        self.position_error, self.velocity_error, self.attitude_error, self.gyro_bias = (
            _Error(self._x[p]) for p in range(4)
        )
        self._camera_rng = rngs["camera_time"]
        self.camera_offset_s = spec.camera_time_offset_s * float(self._camera_rng.standard_normal())
        n = float(np.clip(rngs["thrust"].standard_normal(), -3.0, 3.0))
        self.thrust_scale = 1.0 + spec.thrust_scale_sigma * n
        self.command_delay_s = spec.command_delay_s
        self._delay = DelayLine(spec.lag_s)  # position, velocity
        self._att_delay = DelayLine(spec.att_lag_s)  # attitude, body rates

    def _draw(self) -> None:
        """The next block of normals of each error process's stream."""
        for p, rng in enumerate(self._rngs):
            rng.standard_normal(out=self._normals[p])
        self._k[K_ROW] = 0.0

    def _advance(self, time_s: float) -> None:
        """Step every error process to ``time_s`` (once per distinct time)."""
        if self._k[K_ROW] >= BLOCK:
            self._draw()
        advance_errors(time_s, self._k, self._x, self._normals)

    def hand_off(self, t: float, truth: np.ndarray, noise: Sequence[float], sigma: float):
        """:func:`hand_off`: the gyro sample and the state the loop is handed at ``t`` from
        the vehicle's state array ``truth`` (its rate sums read and zeroed), ``noise`` the
        gyro's white noise draw (standard normal, 3) and ``sigma`` its size (rad/s). Returns
        the 17 floats (an array of its own: the loop may keep views of it)."""
        if self._k[K_ROW] >= BLOCK:
            self._draw()
        out = np.empty(17)
        n0, n1, n2 = noise
        hand_off(
            t, truth, n0, n1, n2, sigma, self._k, self._x, self._normals,
            self._delay.room(), self._att_delay.room(), out,
        )  # fmt: skip
        return out

    def vehicle_state(self, truth: VehicleState) -> VehicleState:
        """The estimate the loop sees at ``truth.time_s``: the truth ``lag_s`` ago with the
        position, velocity and attitude errors, body rates with the gyro bias."""
        return self.vehicle_state_of(
            truth.time_s,
            _floats(truth.position_enu_m),
            _floats(truth.velocity_enu_m_s),
            _floats(truth.attitude_wxyz),
            _floats(truth.body_rates_flu_rad_s),
        )

    def vehicle_state_of(self, t: float, p, v, q, w) -> VehicleState:
        """:meth:`vehicle_state` of the truth at ``t`` given as sequences of floats: position
        (m, ENU), velocity (m/s, ENU), attitude (w, x, y, z) and body rates (rad/s, FLU)
        (the simulator's own state, without making arrays of it first)."""
        pos, vel, att, rates = self.state_floats_of(t, p, v, q, w)
        return VehicleState(t, np.array(pos), np.array(vel), np.array(att), np.array(rates))

    def state_floats_of(self, t: float, p, v, q, w) -> tuple[tuple[float, ...], ...]:
        """:meth:`vehicle_state_of` as tuples of floats (position, velocity, attitude
        (w, x, y, z), body rates) (:func:`estimate_of`)."""
        self._advance(t)
        now = np.array((t, *p, *v, *q, *w), dtype=float)
        out = np.empty(13)
        estimate_of(self._k, self._x, self._delay.room(), self._att_delay.room(), now, out)
        o = out.tolist()
        return tuple(o[0:3]), tuple(o[3:6]), tuple(o[6:10]), tuple(o[10:13])

    def gyro(self, time_s: float, rates_flu_rad_s: np.ndarray) -> np.ndarray:
        """A gyro sample (FLU, rad/s) with the bias at ``time_s`` added."""
        self._advance(time_s)
        (r0, r1, r2), (b0, b1, b2) = _floats(rates_flu_rad_s), self._x[E_BIAS].tolist()
        return np.array([r0 + b0, r1 + b1, r2 + b2])

    def stamp_error_s(self) -> float:
        """The next frame's capture-stamp error (s): the sortie's camera-IMU offset plus this
        frame's jitter (one draw a frame)."""
        return self.camera_offset_s + self.spec.camera_stamp_jitter_s * float(
            self._camera_rng.standard_normal()
        )

    def stamp(self, detection: Detection) -> Detection:
        """The detection as the loop receives it: its capture time off by the sortie's
        camera-IMU offset and the frame's stamp jitter."""
        err = self.stamp_error_s()
        d = detection  # built directly: dataclasses.replace costs more than the rest of this
        return Detection(d.capture_time_s + err, d.center_px, d.bbox_px, d.area_px, d.score)

    def summary(self) -> dict[str, float]:
        """This sortie's draws (for reports): camera offset, thrust scale, gyro bias now."""
        b = self._x[E_BIAS].tolist()
        return {
            "camera_offset_s": self.camera_offset_s,
            "thrust_scale": self.thrust_scale,
            "gyro_bias_x_rad_s": b[0],
            "gyro_bias_y_rad_s": b[1],
            "gyro_bias_z_rad_s": b[2],
        }


def _floats(x) -> list[float]:
    """A vector (ndarray or sequence) as a list of floats."""
    return x.tolist() if isinstance(x, np.ndarray) else [float(c) for c in x]
