"""Rigid-body multicopter with PX4-like inner loops: body rates follow the commanded rates
through a first-order lag (rate-limited per axis), collective thrust through another; body
(quadratic) and rotor (induced, in the rotor plane, proportional to thrust) drag on the
air-relative velocity (docs/air.md). World ENU, body FLU, quaternion (w, x, y, z) body ->
world.

The step is a compiled kernel (:func:`.physics.vehicle_step`) over the state array
:attr:`Multicopter.x`: the simulator's physics kernel runs it for every step between two
events, the SITL vehicle once per step (DESIGN.md §6).
"""

from __future__ import annotations

import math

import numpy as np

from onboard.datatypes import GRAVITY_M_S2, VehicleParams, VehicleState
from onboard.geometry import attitude_from_yaw_pitch_roll, rotmat_to_quat

from ..scenario import InterceptorSpec
from ..scenario.physics import AIR_DENSITY_KG_M3
from .physics import (
    X_ACC,
    X_CMD_THRUST,
    X_CMD_W,
    X_P,
    X_Q,
    X_SIZE,
    X_THRUST,
    X_V,
    X_W,
    gyro_mean,
    vehicle_command,
    vehicle_step,
)

DRAG_REFERENCE_SPEED_M_S = 10.0  # a drawn drag is its equivalent linear value at this speed
ROTOR_SHARE_RANGE = (0.3, 0.7)  # a drawn drag's rotor part, of the whole at the reference speed


def airframe_drag(
    spec: InterceptorSpec, rng: np.random.Generator | None
) -> tuple[float, float, float]:
    """(linear N s/m, body C_d A m^2, rotor N s/m at hover thrust) of one sortie: the spec's
    values, or where it gives a range (``drag_max_n_s_m`` > 0) a draw: the equivalent drag at
    :data:`DRAG_REFERENCE_SPEED_M_S` uniform in [min, max], its rotor share uniform in
    :data:`ROTOR_SHARE_RANGE`, the rest quadratic body drag (the range's middle and an even
    split without ``rng``)."""
    if not spec.drag_max_n_s_m > 0.0:
        return spec.drag_n_s_m, spec.drag_area_m2, spec.rotor_drag_n_s_m
    lo, hi = spec.drag_min_n_s_m, spec.drag_max_n_s_m
    if rng is None:
        total, share = 0.5 * (lo + hi), 0.5 * sum(ROTOR_SHARE_RANGE)
    else:
        total, share = float(rng.uniform(lo, hi)), float(rng.uniform(*ROTOR_SHARE_RANGE))
    body_area = (1.0 - share) * total / (0.5 * AIR_DENSITY_KG_M3 * DRAG_REFERENCE_SPEED_M_S)
    return 0.0, body_area, share * total


def _slot(i: int, n: int) -> property:
    """A list view of x[i:i+n] (a copy: assign the whole vector to change it)."""

    def get(self: Multicopter) -> list[float]:
        return self.x[i : i + n].tolist()

    def put(self: Multicopter, value) -> None:
        self.x[i : i + n] = value

    return property(get, put)


def _scalar(i: int) -> property:
    def get(self: Multicopter) -> float:
        return float(self.x[i])

    def put(self: Multicopter, value: float) -> None:
        self.x[i] = value

    return property(get, put)


class Multicopter:
    """The vehicle: its state in :attr:`x` (X_* layout), read and written as lists through
    ``p``, ``v``, ``q``, ``w``, ``accel``, ``cmd_w`` (copies: assign a whole vector) and
    floats ``thrust_n``, ``cmd_thrust_n``."""

    p = _slot(X_P, 3)
    v = _slot(X_V, 3)
    q = _slot(X_Q, 4)
    w = _slot(X_W, 3)
    accel = _slot(X_ACC, 3)  # kinematic acceleration of the last step
    cmd_w = _slot(X_CMD_W, 3)
    thrust_n = _scalar(X_THRUST)
    cmd_thrust_n = _scalar(X_CMD_THRUST)

    def __init__(self, spec: InterceptorSpec, rng: np.random.Generator | None = None) -> None:
        """``rng``: draws this sortie's airframe drag where the spec gives a range
        (``drag_max_n_s_m`` > 0); without it the range's middle with an even split."""
        self.spec = spec
        self.drag_n_s_m, self.drag_area_m2, self.rotor_drag_n_s_m = airframe_drag(spec, rng)
        self.params = VehicleParams(
            mass_kg=spec.mass_kg, max_thrust_n=spec.thrust_to_weight * spec.mass_kg * GRAVITY_M_S2
        )
        self.x = np.zeros(X_SIZE)
        self.p = list(spec.position_m)
        self.v = list(spec.velocity_m_s)
        q0 = rotmat_to_quat(attitude_from_yaw_pitch_roll(math.radians(spec.yaw_deg)))
        self.q = [float(c) for c in q0]
        self.thrust_n = self.cmd_thrust_n = spec.mass_kg * GRAVITY_M_S2
        self.max_rate_rad_s = math.radians(spec.max_rate_deg_s)
        self._lag_dt = -1.0
        self._lag = np.zeros(4)

    def lag(self, dt: float) -> np.ndarray:
        """The per-step-size constants for steps of ``dt`` (s) (L_* layout), computed once
        per step size."""
        if dt != self._lag_dt:
            s = self.spec
            self._lag_dt = dt
            hover_n = s.mass_kg * GRAVITY_M_S2
            self._lag = np.array(
                [
                    1.0 - math.exp(-dt / s.rate_time_constant_s),
                    1.0 - math.exp(-dt / s.thrust_time_constant_s),
                    self.drag_n_s_m / s.mass_kg,
                    s.mass_kg,
                    0.5 * AIR_DENSITY_KG_M3 * self.drag_area_m2 / s.mass_kg,
                    self.rotor_drag_n_s_m / (s.mass_kg * hover_n),
                    s.rotor_disc_area_m2,
                ]
            )
        return self._lag

    def drag_equivalent_n_s_m(self, airspeed_m_s: float = DRAG_REFERENCE_SPEED_M_S) -> float:
        """The airframe's drag in level flight at hover thrust at ``airspeed_m_s`` (m/s), over
        that speed (N s/m): what one linear coefficient would stand for there."""
        body = 0.5 * AIR_DENSITY_KG_M3 * self.drag_area_m2 * airspeed_m_s
        return self.drag_n_s_m + self.rotor_drag_n_s_m + body

    def command(self, body_rates_flu_rad_s: np.ndarray, thrust_normalised: float) -> None:
        """Body rates (rad/s FLU, clamped to the rate limit per axis) and normalised thrust
        (clamped to [0, 1]): they take effect at the next step
        (:func:`.physics.vehicle_command`)."""
        w = body_rates_flu_rad_s
        vehicle_command(
            self.x,
            self.max_rate_rad_s,
            self.params.max_thrust_n,
            float(w[0]),
            float(w[1]),
            float(w[2]),
            float(thrust_normalised),
        )

    def step(self, dt: float, wind: tuple[float, float, float]) -> None:
        """Advance one step of ``dt`` (s) in ``wind`` (m/s, ENU): :func:`vehicle_step`."""
        vehicle_step(self.x, self.lag(dt), dt, wind[0], wind[1], wind[2])

    def read_gyro(self) -> list[float]:
        """Mean body rate since the previous read (:func:`.physics.gyro_mean`)."""
        return list(gyro_mean(self.x))

    def state(self, time_s: float) -> VehicleState:
        x = self.x
        return VehicleState(
            time_s=time_s,
            position_enu_m=x[X_P : X_P + 3].copy(),
            velocity_enu_m_s=x[X_V : X_V + 3].copy(),
            attitude_wxyz=x[X_Q : X_Q + 4].copy(),
            body_rates_flu_rad_s=x[X_W : X_W + 3].copy(),
        )

    def finite(self) -> bool:
        # a NaN or inf anywhere makes the sum non-finite
        p, v, q, w = self.p, self.v, self.q, self.w
        return math.isfinite(
            p[0] + p[1] + p[2] + v[0] + v[1] + v[2] + q[0] + q[1] + q[2] + q[3] + w[0] + w[1] + w[2]
        )
