"""The vehicle's own velocity, complementary-filtered: the state estimate's velocity (EKF2's
output, lag-compensated by the loop) for the slow part, the acceleration the loop models for
the fast part:

    v_f' = a + (v - v_f) / tau_c,      a = (T / m) z_B - g e_z + D

with T the collective thrust the loop last commanded, z_B the thrust axis, D the drag and
disturbance it believes (the airframe's drag model plus the observer's d^,
:func:`onboard.control.png.believed_drag_floats`). From v to v_f the transfer is the low-pass
1 / (1 + tau_c s); from the true acceleration it is 1 (a modelled manoeuvre is followed at
once), and an acceleration the model misses by a_err leaves a bias a_err tau_c.

Why: a GNSS-aided estimate's velocity error is a slow wander whose increments are close to
white at the loop's rate (the first-order Gauss-Markov model of the simulator's outdoor
profile: sigma 0.1-0.2 m/s, 1 s). Its slow part cancels in the DKF's relative motion (the
target-velocity states absorb it); its fast part is an apparent relative acceleration that the
DKF integrates through a burst of dropped frames, which is where a tail sortie flies its last
metres. Passing that part through the low-pass keeps it out of the relative motion.

Discretely, over a tick of dt the held acceleration of the last interval is integrated and the
result moved a fraction 1 - exp(-dt / tau_c) towards v (exact for a constant v and a). With
tau_c = 0 the fraction is 1: v_f is v, to the bit. A non-finite input or a velocity jump larger
than ``max_innovation_m_s`` (an estimator reset) restarts the filter at v.
"""

from __future__ import annotations

import math

from ..datatypes import GRAVITY_M_S2

Vec3 = tuple[float, float, float]


class OwnVelocityFilter:
    """Call :meth:`update` once per control tick with the elapsed time (s) and the velocity
    the loop uses (ENU, m/s), then :meth:`set_accel` with the specific acceleration it
    commands for the coming interval (ENU, m/s^2, gravity included)."""

    __slots__ = ("_a", "_v", "max_innovation_m_s", "tau_s")

    def __init__(self, tau_s: float, max_innovation_m_s: float = 2.0) -> None:
        self.tau_s = 0.0
        self.set_time_constant(tau_s)
        if not (math.isfinite(max_innovation_m_s) and max_innovation_m_s > 0.0):
            raise ValueError(f"own-velocity max innovation {max_innovation_m_s!r} must be > 0")
        self.max_innovation_m_s = float(max_innovation_m_s)
        self._v: Vec3 | None = None  # the filtered velocity (m/s, ENU); None: restart at v
        self._a: Vec3 = (0.0, 0.0, 0.0)  # the acceleration held since the last tick (m/s^2)

    def set_time_constant(self, tau_s: float) -> None:
        """Change tau_c (s, >= 0; 0: the filter passes v through); the state is kept."""
        if not (isinstance(tau_s, (int, float)) and math.isfinite(tau_s) and tau_s >= 0.0):
            raise ValueError(f"own-velocity time constant {tau_s!r} must be finite and >= 0")
        self.tau_s = float(tau_s)

    def reset(self) -> None:
        """Forget the state: the next update starts at its v."""
        self._v = None
        self._a = (0.0, 0.0, 0.0)

    @property
    def velocity_enu_m_s(self) -> Vec3 | None:
        """The filtered velocity after the last update (None before the first)."""
        return self._v

    def update(self, dt_s: float, v0: float, v1: float, v2: float) -> Vec3:
        """The filtered velocity at this tick, ``dt_s`` after the last, from the velocity
        (v0, v1, v2) (m/s, ENU). tau_c = 0, a first call, a non-finite input or a reset-sized
        innovation: v itself."""
        prev = self._v
        if self.tau_s == 0.0:
            self._v = (v0, v1, v2)
            return v0, v1, v2
        if (
            prev is None
            or not (math.isfinite(v0) and math.isfinite(v1) and math.isfinite(v2))
            or not (math.isfinite(dt_s) and dt_s >= 0.0)
        ):
            self._v = (v0, v1, v2) if math.isfinite(v0 + v1 + v2) else None
            return v0, v1, v2
        a0, a1, a2 = self._a
        p0, p1, p2 = prev[0] + dt_s * a0, prev[1] + dt_s * a1, prev[2] + dt_s * a2
        e0, e1, e2 = v0 - p0, v1 - p1, v2 - p2
        if math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) > self.max_innovation_m_s:
            self._v = (v0, v1, v2)
            return v0, v1, v2
        k = -math.expm1(-dt_s / self.tau_s)  # 1 - exp(-dt / tau_c)
        self._v = out = (p0 + k * e0, p1 + k * e1, p2 + k * e2)
        return out

    def set_thrust(
        self, k: float, z0: float, z1: float, z2: float, d0: float, d1: float, d2: float
    ) -> None:
        """:meth:`set_accel` of thrust per mass ``k`` (m/s^2) along the thrust axis
        (z0, z1, z2) (ENU, unit), gravity and the believed drag and disturbance (d0, d1, d2)
        (m/s^2, ENU)."""
        self.set_accel(z0 * k + d0, z1 * k + d1, z2 * k - GRAVITY_M_S2 + d2)

    def set_accel(self, a0: float, a1: float, a2: float) -> None:
        """The specific acceleration (m/s^2, ENU) held until the next update; a non-finite
        one is taken as 0 (the correction alone then carries the filter)."""
        if math.isfinite(a0) and math.isfinite(a1) and math.isfinite(a2):
            self._a = (a0, a1, a2)
        else:
            self._a = (0.0, 0.0, 0.0)
