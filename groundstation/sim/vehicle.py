"""Rigid-body multicopter with PX4-like inner loops: body rates follow the commanded rates
through a first-order lag (rate-limited per axis), collective thrust through another; linear
drag on the air-relative velocity. World ENU, body FLU, quaternion (w, x, y, z) body -> world.

The step runs in plain floats: it is the simulator's hot path (DESIGN.md §6).
"""

from __future__ import annotations

import math

import numpy as np

from onboard.datatypes import GRAVITY_M_S2, VehicleParams, VehicleState
from onboard.geometry import attitude_from_yaw_pitch_roll, rotmat_to_quat

from ..scenario import InterceptorSpec


class Multicopter:
    def __init__(self, spec: InterceptorSpec) -> None:
        self.spec = spec
        self.params = VehicleParams(
            mass_kg=spec.mass_kg, max_thrust_n=spec.thrust_to_weight * spec.mass_kg * GRAVITY_M_S2
        )
        self.p = list(spec.position_m)
        self.v = list(spec.velocity_m_s)
        q0 = rotmat_to_quat(attitude_from_yaw_pitch_roll(math.radians(spec.yaw_deg)))
        self.q = [float(c) for c in q0]
        self.w = [0.0, 0.0, 0.0]
        self.thrust_n = spec.mass_kg * GRAVITY_M_S2
        self.cmd_w = [0.0, 0.0, 0.0]
        self.cmd_thrust_n = self.thrust_n
        self.accel = [0.0, 0.0, 0.0]  # kinematic acceleration of the last step
        self._rate_sum = [0.0, 0.0, 0.0]  # body rates summed since the last gyro read
        self._rate_n = 0
        self._max_rate = math.radians(spec.max_rate_deg_s)
        self._lag_dt = -1.0
        self._aw = self._at = 0.0

    def command(self, body_rates_flu_rad_s: np.ndarray, thrust_normalised: float) -> None:
        lim = self._max_rate
        self.cmd_w = [min(max(float(c), -lim), lim) for c in body_rates_flu_rad_s]
        t = min(max(float(thrust_normalised), 0.0), 1.0)
        self.cmd_thrust_n = t * self.params.max_thrust_n

    def step(self, dt: float, wind: tuple[float, float, float]) -> None:
        s = self.spec
        if dt != self._lag_dt:  # first-order lag factors, computed once per step size
            self._lag_dt = dt
            self._aw = 1.0 - math.exp(-dt / s.rate_time_constant_s)
            self._at = 1.0 - math.exp(-dt / s.thrust_time_constant_s)
        aw, at = self._aw, self._at
        w = self.w
        cw = self.cmd_w
        w0, w1, w2 = (
            w[0] + (cw[0] - w[0]) * aw,
            w[1] + (cw[1] - w[1]) * aw,
            w[2] + (cw[2] - w[2]) * aw,
        )
        self.w = [w0, w1, w2]
        rs = self._rate_sum
        rs[0] += w0
        rs[1] += w1
        rs[2] += w2
        self._rate_n += 1
        self.thrust_n += (self.cmd_thrust_n - self.thrust_n) * at
        # attitude: q <- q (x) exp(w dt / 2)
        qw, qx, qy, qz = self.q
        ang = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2) * dt
        if ang > 1e-12:
            h = 0.5 * ang
            sh = math.sin(h) / (ang / dt)
            dw, dx, dy, dz = math.cos(h), w0 * sh, w1 * sh, w2 * sh
            qw, qx, qy, qz = (
                qw * dw - qx * dx - qy * dy - qz * dz,
                qw * dx + qx * dw + qy * dz - qz * dy,
                qw * dy - qx * dz + qy * dw + qz * dx,
                qw * dz + qx * dy - qy * dx + qz * dw,
            )
            n = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
            qw, qx, qy, qz = qw * n, qx * n, qy * n, qz * n
            self.q = [qw, qx, qy, qz]
        # thrust axis z_B in the world
        zx = 2.0 * (qx * qz + qw * qy)
        zy = 2.0 * (qy * qz - qw * qx)
        zz = 1.0 - 2.0 * (qx * qx + qy * qy)
        m = s.mass_kg
        ft = self.thrust_n / m
        kd = s.drag_n_s_m / m
        v = self.v
        ax = ft * zx - kd * (v[0] - wind[0])
        ay = ft * zy - kd * (v[1] - wind[1])
        az = ft * zz - kd * (v[2] - wind[2]) - GRAVITY_M_S2
        self.accel = [ax, ay, az]
        vx, vy, vz = v[0] + ax * dt, v[1] + ay * dt, v[2] + az * dt
        self.v = [vx, vy, vz]
        p = self.p
        self.p = [p[0] + vx * dt, p[1] + vy * dt, p[2] + vz * dt]

    def read_gyro(self) -> list[float]:
        """Mean body rate since the previous read (what averaging IMU samples yields)."""
        if self._rate_n == 0:
            return list(self.w)
        n = self._rate_n
        out = [c / n for c in self._rate_sum]
        self._rate_sum = [0.0, 0.0, 0.0]
        self._rate_n = 0
        return out

    def state(self, time_s: float) -> VehicleState:
        return VehicleState(
            time_s=time_s,
            position_enu_m=np.array(self.p),
            velocity_enu_m_s=np.array(self.v),
            attitude_wxyz=np.array(self.q),
            body_rates_flu_rad_s=np.array(self.w),
        )

    def finite(self) -> bool:
        # a NaN or inf anywhere makes the sum non-finite
        p, v, q, w = self.p, self.v, self.q, self.w
        return math.isfinite(
            p[0] + p[1] + p[2] + v[0] + v[1] + v[2] + q[0] + q[1] + q[2] + q[3] + w[0] + w[1] + w[2]
        )
