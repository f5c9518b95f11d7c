"""Rigid-body multicopter with PX4-like inner loops: body rates follow the commanded rates
through a first-order lag (rate-limited per axis), collective thrust through another; linear
drag on the air-relative velocity. World ENU, body FLU, quaternion (w, x, y, z) body -> world.

The step runs in plain floats: it is the simulator's hot path (DESIGN.md §6).
"""

from __future__ import annotations

import math
from collections.abc import Generator

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
        self._mass_kg = spec.mass_kg
        self._aw = self._at = self._kd = 0.0

    def command(self, body_rates_flu_rad_s: np.ndarray, thrust_normalised: float) -> None:
        lim = self._max_rate
        w = (
            body_rates_flu_rad_s.tolist()
            if isinstance(body_rates_flu_rad_s, np.ndarray)
            else body_rates_flu_rad_s
        )
        c0, c1, c2 = w
        c0, c1, c2 = float(c0), float(c1), float(c2)
        # min(max(c, -lim), lim) per axis, written out (a NaN stays NaN either way)
        if c0 < -lim:
            c0 = -lim
        if c0 > lim:
            c0 = lim
        if c1 < -lim:
            c1 = -lim
        if c1 > lim:
            c1 = lim
        if c2 < -lim:
            c2 = -lim
        if c2 > lim:
            c2 = lim
        self.cmd_w = [c0, c1, c2]
        t = min(max(float(thrust_normalised), 0.0), 1.0)
        self.cmd_thrust_n = t * self.params.max_thrust_n

    def step(self, dt: float, wind: tuple[float, float, float]) -> None:
        """Advance one step of ``dt`` (s) in ``wind`` (m/s, ENU): :meth:`integrate` for one
        step."""
        steps = self.integrate(dt)
        steps.send(None)
        steps.send(wind)
        steps.close()

    def integrate(self, dt: float) -> Generator[tuple, tuple[float, float, float], None]:
        """The dynamics, a step of ``dt`` (s) per wind sent (m/s, ENU, where the vehicle is
        at the start of the step): prime with ``send(None)``, then each ``send(wind)`` steps
        and returns ``(px, py, pz, vx, vy, vz, s)`` after the step, ``s`` the sum of position,
        velocity, attitude and body rates (finite iff they all are, as :meth:`finite`). The
        state lives in locals between sends and is written back when the generator closes
        (``close()``): a simulator runs the steps between two control ticks in one of these.
        Commands (:meth:`command`) given between sends take effect at the next step."""
        if dt != self._lag_dt:  # per-step-size constants, computed once
            s = self.spec
            self._lag_dt = dt
            self._aw = 1.0 - math.exp(-dt / s.rate_time_constant_s)
            self._at = 1.0 - math.exp(-dt / s.thrust_time_constant_s)
            self._kd = s.drag_n_s_m / s.mass_kg
        aw, at, kd, mass = self._aw, self._at, self._kd, self._mass_kg
        w0, w1, w2 = self.w
        qw, qx, qy, qz = self.q
        vx, vy, vz = self.v
        px, py, pz = self.p
        ax, ay, az = self.accel
        thrust_n = self.thrust_n
        rs0, rs1, rs2 = self._rate_sum
        rate_n = self._rate_n
        n_steps = 0
        try:
            wind = yield ()
            while True:
                c0, c1, c2 = self.cmd_w
                w0 += (c0 - w0) * aw
                w1 += (c1 - w1) * aw
                w2 += (c2 - w2) * aw
                rs0 += w0
                rs1 += w1
                rs2 += w2
                thrust_n += (self.cmd_thrust_n - thrust_n) * at
                # attitude: q <- q (x) exp(w dt / 2)
                rate = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
                ang = rate * dt
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
                # thrust axis z_B in the world
                ft = thrust_n / mass
                ax = ft * (2.0 * (qx * qz + qw * qy)) - kd * (vx - wind[0])
                ay = ft * (2.0 * (qy * qz - qw * qx)) - kd * (vy - wind[1])
                az = ft * (1.0 - 2.0 * (qx * qx + qy * qy)) - kd * (vz - wind[2]) - GRAVITY_M_S2
                vx += ax * dt
                vy += ay * dt
                vz += az * dt
                px, py, pz = px + vx * dt, py + vy * dt, pz + vz * dt
                n_steps += 1
                wind = yield (
                    px,
                    py,
                    pz,
                    vx,
                    vy,
                    vz,
                    px + py + pz + vx + vy + vz + qw + qx + qy + qz + w0 + w1 + w2,
                )
        finally:
            if n_steps:
                self.w = [w0, w1, w2]
                self.q = [qw, qx, qy, qz]
                self.v = [vx, vy, vz]
                self.p = [px, py, pz]
                self.accel = [ax, ay, az]
                self.thrust_n = thrust_n
                self._rate_sum = [rs0, rs1, rs2]
                self._rate_n = rate_n + n_steps

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
