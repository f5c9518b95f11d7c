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
attitude (att_noise_deg,      0.2 deg, Gauss-Markov small rotation per body axis. EKF2's tilt
att_time_constant_s)          2 s      is held by accelerometer/velocity fusion to a few
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
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from onboard.datatypes import Detection, VehicleState
from onboard.geometry import quat_exp_floats, quat_mul_floats

from ..scenario import EstimateSpec

# the independent random streams, in spawn order (a new error goes at the end)
STREAMS = ("position", "velocity", "attitude", "gyro_bias", "camera_time", "thrust")


class Normals:
    """Standard normal vectors of one stream as lists of floats, drawn a block at a time (one
    call per 256 samples instead of one each: the stream's sequence does not depend on the
    block)."""

    def __init__(self, rng: np.random.Generator, dim: int, block: int = 256) -> None:
        self._rng, self._dim, self._block = rng, dim, block
        self._buf: list[list[float]] = []
        self._i = 0

    def next(self) -> list[float]:
        i = self._i
        if i >= len(self._buf):
            self._buf = self._rng.standard_normal((self._block, self._dim)).tolist()
            i = 0
        self._i = i + 1
        return self._buf[i]


class GaussMarkov:
    """First-order Gauss-Markov process per component, x' = -x / tau + w, stationary standard
    deviation ``sigma``; started in its stationary distribution and stepped exactly for any
    dt (x <- a x + sigma sqrt(1 - a^2) n, a = exp(-dt / tau)). Kept as floats (:attr:`x`;
    :attr:`value` is the same as an array): numpy's per-call cost on a 3-vector is several
    times the arithmetic, which is the same operations in the same order."""

    def __init__(self, sigma: float, tau_s: float, dim: int, rng: np.random.Generator) -> None:
        self.sigma = float(sigma)
        self.tau_s = float(tau_s)
        self._normals = Normals(rng, dim)
        self._three = dim == 3
        s = self.sigma
        self.x = [s * n for n in self._normals.next()]
        self._dt_s = -1.0
        self._a = self._b = 0.0

    @property
    def value(self) -> np.ndarray:
        return np.array(self.x)

    def step(self, dt_s: float) -> list[float]:
        if dt_s != self._dt_s:  # the factors, once per step size
            self._dt_s = dt_s
            self._a = math.exp(-dt_s / self.tau_s)
            self._b = self.sigma * math.sqrt(1.0 - self._a * self._a)
        a, b, x, n = self._a, self._b, self.x, self._normals.next()
        if self._three:  # the estimate's vectors, written out (a comprehension costs twice)
            self.x = [a * x[0] + b * n[0], a * x[1] + b * n[1], a * x[2] + b * n[2]]
        else:
            self.x = [a * xi + b * ni for xi, ni in zip(x, n, strict=True)]
        return self.x


class RandomWalk:
    """A bias: N(0, ``initial``) per component at the start, then a random walk of
    ``walk_per_sqrt_s`` (its standard deviation grows as walk x sqrt(t)). Floats as
    :class:`GaussMarkov`."""

    def __init__(
        self, initial: float, walk_per_sqrt_s: float, dim: int, rng: np.random.Generator
    ) -> None:
        self.walk = float(walk_per_sqrt_s)
        self._normals = Normals(rng, dim)
        self._three = dim == 3
        s = float(initial)
        self.x = [s * n for n in self._normals.next()]

    @property
    def value(self) -> np.ndarray:
        return np.array(self.x)

    def step(self, dt_s: float) -> list[float]:
        s, x, n = self.walk * math.sqrt(dt_s), self.x, self._normals.next()
        if self._three:  # as GaussMarkov.step
            self.x = [x[0] + s * n[0], x[1] + s * n[1], x[2] + s * n[2]]
        else:
            self.x = [xi + s * ni for xi, ni in zip(x, n, strict=True)]
        return self.x


@dataclass(slots=True)  # not frozen (read-only by convention): three are made a tick
class _Sample:
    """One sample of the truth: time, position, velocity, attitude (w, x, y, z) and body rates
    (sequences of floats)."""

    time_s: float
    p: tuple
    v: tuple
    q: tuple
    w: tuple


def _lerp3(a, b, f: float) -> tuple[float, float, float]:
    return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))


class DelayLine:
    """The truth ``lag_s`` ago, linearly interpolated between the samples pushed (quaternions
    normalised after interpolation); before the history reaches back that far, the oldest
    sample. With ``lag_s = 0`` it returns the newest sample unchanged."""

    def __init__(self, lag_s: float) -> None:
        self.lag_s = float(lag_s)
        self._hist: deque[_Sample] = deque()

    def push(self, s: _Sample) -> _Sample:
        h = self._hist
        h.append(s)
        tq = s.time_s - self.lag_s
        tq_eps = tq + 1e-12
        while len(h) >= 2 and h[1].time_s <= tq_eps:
            h.popleft()
        a = h[0]
        if len(h) == 1 or tq <= a.time_s + 1e-12:
            return a
        b = h[1]
        f = (tq - a.time_s) / (b.time_s - a.time_s)
        a0, a1, a2, a3 = a.q
        b0, b1, b2, b3 = b.q
        if not a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 >= 0.0:
            b0, b1, b2, b3 = -b0, -b1, -b2, -b3
        q0, q1, q2, q3 = (
            a0 + f * (b0 - a0),
            a1 + f * (b1 - a1),
            a2 + f * (b2 - a2),
            a3 + f * (b3 - a3),
        )
        n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        return _Sample(
            tq,
            _lerp3(a.p, b.p, f),
            _lerp3(a.v, b.v, f),
            (q0 / n, q1 / n, q2 / n, q3 / n),
            _lerp3(a.w, b.w, f),
        )


class StateEstimateModel:
    """The errors of one sortie (see the module docstring). Call :meth:`vehicle_state` and
    :meth:`gyro` at each control tick (time non-decreasing), :meth:`stamp` on each delivered
    detection; :attr:`thrust_scale` and :attr:`command_delay_s` shape the actuation."""

    def __init__(self, spec: EstimateSpec, seed: np.random.SeedSequence) -> None:
        self.spec = spec
        rngs = dict(
            zip(STREAMS, (np.random.default_rng(s) for s in seed.spawn(len(STREAMS))), strict=True)
        )
        self.position_error = GaussMarkov(
            spec.pos_noise_m, spec.pos_time_constant_s, 3, rngs["position"]
        )
        self.velocity_error = GaussMarkov(
            spec.vel_noise_m_s, spec.vel_time_constant_s, 3, rngs["velocity"]
        )
        self.attitude_error = GaussMarkov(
            math.radians(spec.att_noise_deg), spec.att_time_constant_s, 3, rngs["attitude"]
        )
        self.gyro_bias = RandomWalk(
            spec.gyro_bias_rad_s, spec.gyro_bias_walk_rad_s_sqrt_s, 3, rngs["gyro_bias"]
        )
        self._camera_rng = rngs["camera_time"]
        self.camera_offset_s = spec.camera_time_offset_s * float(self._camera_rng.standard_normal())
        n = float(np.clip(rngs["thrust"].standard_normal(), -3.0, 3.0))
        self.thrust_scale = 1.0 + spec.thrust_scale_sigma * n
        self.command_delay_s = spec.command_delay_s
        self._delay = DelayLine(spec.lag_s)  # position, velocity
        self._att_delay = DelayLine(spec.att_lag_s)  # attitude, body rates
        self._time_s: float | None = None

    def _advance(self, time_s: float) -> None:
        """Step every error process to ``time_s`` (once per distinct time)."""
        if self._time_s is not None:
            dt = time_s - self._time_s
            if dt <= 0.0:
                return
            self.position_error.step(dt)
            self.velocity_error.step(dt)
            self.attitude_error.step(dt)
            self.gyro_bias.step(dt)
        self._time_s = time_s

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
        (w, x, y, z), body rates), for a caller that makes its own arrays (or none)."""
        self._advance(t)
        now = _Sample(t, p, v, q, w)
        old = self._delay.push(now)
        old_att = self._att_delay.push(now)
        (p0, p1, p2), (e0, e1, e2) = old.p, self.position_error.x
        (v0, v1, v2), (u0, u1, u2) = old.v, self.velocity_error.x
        (w0, w1, w2), (b0, b1, b2) = old_att.w, self.gyro_bias.x
        return (
            (p0 + e0, p1 + e1, p2 + e2),
            (v0 + u0, v1 + u1, v2 + u2),
            # a unit quaternion times a unit quaternion: no renormalising, so that zero
            # errors hand the loop the truth bit for bit
            quat_mul_floats(old_att.q, quat_exp_floats(self.attitude_error.x)),
            (w0 + b0, w1 + b1, w2 + b2),
        )

    def gyro(self, time_s: float, rates_flu_rad_s: np.ndarray) -> np.ndarray:
        """A gyro sample (FLU, rad/s) with the bias at ``time_s`` added."""
        self._advance(time_s)
        (r0, r1, r2), (b0, b1, b2) = _floats(rates_flu_rad_s), self.gyro_bias.x
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
        return replace(detection, capture_time_s=detection.capture_time_s + err)

    def summary(self) -> dict[str, float]:
        """This sortie's draws (for reports): camera offset, thrust scale, gyro bias now."""
        b = self.gyro_bias.x
        return {
            "camera_offset_s": self.camera_offset_s,
            "thrust_scale": self.thrust_scale,
            "gyro_bias_x_rad_s": float(b[0]),
            "gyro_bias_y_rad_s": float(b[1]),
            "gyro_bias_z_rad_s": float(b[2]),
        }


def _floats(x) -> list[float]:
    """A vector (ndarray or sequence) as a list of floats."""
    return x.tolist() if isinstance(x, np.ndarray) else [float(c) for c in x]
