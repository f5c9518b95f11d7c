"""Disturbance observer: the unmodelled specific force d in the translational dynamics

    v' = (T / m) z_B - g e_z + d                      (paper eq. 23's model, plus d)

estimated from what the loop really has at each tick: the velocity of the state estimate, the
attitude (the *achieved* thrust axis z_B, not the commanded one) and the collective thrust the
loop itself commanded, passed through the motors' first-order lag. d is drag (on the air-relative
velocity: wind), a thrust-model error, a tether or payload pull: whatever eq. 17 does not model.
Feeding -d^ forward into the acceleration handed to the attitude loop (onboard/loop.py) cancels
it below the observer bandwidth, as a disturbance observer does (Chen et al., "Disturbance-
observer-based control and related methods - an overview", IEEE TIE 63(2), 2016; the extended
state observer of Han, IEEE TIE 56(3), 2009).

The observer is a second-order extended state observer on (v, d), both poles at -w (critically
damped), w = ``k_dob`` (1/s); discretely, both error poles at exp(-w dt) whatever the tick dt:

    v^' = f_model + d^ + 2 w (v - v^)
    d^' = w^2 (v - v^)

From d to d^ the transfer is w^2 / (s + w)^2: a constant disturbance is recovered with no
steady-state error (to 2 % within 5.8 / w s). From velocity noise to d^ it is
w^2 s / (s + w)^2, a band-pass that peaks near w; with white velocity noise of sigma_v per
sample at period T the standard deviation of d^ is about sigma_v w sqrt(w T) / 2 (0.007 m/s^2
for 0.05 m/s, w = 2 1/s, 100 Hz). Using the measured attitude means a manoeuvre, which the
attitude loop achieves with a lag, is in f_model as flown and does not leak into d^; the
thrust magnitude is the only modelled actuator, through ``thrust_time_constant_s``. The
bandwidth should stay well below the attitude loop's (k_R = 8 1/s) so that what remains of
the actuator and state-estimate lag (tens of ms) stays out of d^.

From a cold start (the first update) the bandwidth is max(w, ``start_factor`` / t), t the time
since the start: the estimate converges in a few ticks of hover, then settles to w (a growing-
memory start, what a Kalman filter with a large initial covariance does); a sortie that starts
in the wind does not wait 5.8 / w s for d^.

Robustness: |d^| is clamped to ``max_m_s2``; a non-finite input skips the update (the estimate
is held, never NaN); a velocity jump larger than ``max_innovation_m_s`` (an estimator reset)
restarts the velocity state without touching d^.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..datatypes import GRAVITY_M_S2


@dataclass(frozen=True, slots=True)
class DisturbanceObserverConfig:
    """Observer settings: ``bandwidth_rad_s`` w (0 disables: d^ = 0), the motors' thrust lag
    (s), the clamp on |d^| (m/s^2), the velocity innovation treated as a reset (m/s), the
    cold-start factor (see the module doc) and the airframe's linear drag per unit mass
    (1/s, PX4 EKF2_MCOEF's rotor-drag model) counted in the model, so that d^ is what the
    *wind* adds, c w, not the airframe's own drag -c v, which turns with the velocity."""

    bandwidth_rad_s: float
    mass_kg: float
    max_thrust_n: float
    thrust_time_constant_s: float = 0.03
    max_m_s2: float = 5.0
    max_innovation_m_s: float = 2.0
    start_factor: float = 3.0
    drag_per_mass_1_s: float = 0.0

    def __post_init__(self) -> None:
        checks = (
            ("bandwidth_rad_s", self.bandwidth_rad_s >= 0.0),
            ("mass_kg", self.mass_kg > 0.0),
            ("max_thrust_n", self.max_thrust_n > 0.0),
            ("thrust_time_constant_s", self.thrust_time_constant_s >= 0.0),
            ("max_m_s2", self.max_m_s2 >= 0.0),
            ("max_innovation_m_s", self.max_innovation_m_s > 0.0),
            ("start_factor", self.start_factor >= 0.0),
            ("drag_per_mass_1_s", self.drag_per_mass_1_s >= 0.0),
        )
        for name, ok in checks:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and ok):
                raise ValueError(f"disturbance observer {name} = {value!r} is out of range")


def _finite3(x: np.ndarray) -> bool:
    return x.shape == (3,) and bool(np.all(np.isfinite(x)))


class DisturbanceObserver:
    """Call :meth:`update` once per control tick with the state the loop was given, then
    :meth:`commanded` with the normalised thrust it sends; :attr:`estimate_m_s2` is d^ (ENU)."""

    def __init__(self, config: DisturbanceObserverConfig) -> None:
        self.config = config
        self.estimate_m_s2 = np.zeros(3)
        self._v_hat: np.ndarray | None = None
        self._z_prev: np.ndarray | None = None
        self._t_prev: float | None = None
        self._elapsed_s = 0.0
        self._thrust_n = config.mass_kg * GRAVITY_M_S2  # modelled achieved thrust
        self._thrust_cmd_n: float | None = None  # in force since the previous update
        self.resets = 0

    @property
    def enabled(self) -> bool:
        return self.config.bandwidth_rad_s > 0.0

    def set_bandwidth(
        self, bandwidth_rad_s: float, max_m_s2: float, drag_per_mass_1_s: float
    ) -> None:
        """Change w, the clamp and the drag model (a gain change in flight); w = 0 disables
        and clears d^. An invalid value raises ValueError and changes nothing."""
        self.config = dataclasses.replace(
            self.config,
            bandwidth_rad_s=bandwidth_rad_s,
            max_m_s2=max_m_s2,
            drag_per_mass_1_s=drag_per_mass_1_s,
        )
        if not self.enabled:
            self.estimate_m_s2 = np.zeros(3)
            self._v_hat = None

    def commanded(self, thrust_normalised: float) -> None:
        """The collective thrust (normalised, [0, 1]) sent at this tick, in force until the
        next :meth:`update`; a non-finite value is ignored (the previous command holds)."""
        if math.isfinite(thrust_normalised):
            t = min(max(thrust_normalised, 0.0), 1.0)
            self._thrust_cmd_n = t * self.config.max_thrust_n

    def update(
        self, time_s: float, velocity_enu_m_s: np.ndarray, thrust_axis_enu: np.ndarray
    ) -> np.ndarray:
        """Advance to ``time_s`` with the measured velocity (m/s) and body z axis in the world
        (unit); returns d^ (m/s^2, ENU). Bad or out-of-order input holds the estimate."""
        v = np.asarray(velocity_enu_m_s, dtype=float)
        z = np.asarray(thrust_axis_enu, dtype=float)
        if not (math.isfinite(time_s) and _finite3(v) and _finite3(z)):
            return self.estimate_m_s2
        zn = math.sqrt(float(z @ z))
        if not zn > 0.5:
            return self.estimate_m_s2
        z = z / zn
        c = self.config
        if not self.enabled:
            self._t_prev, self._z_prev = time_s, z
            return self.estimate_m_s2
        if self._v_hat is None or self._t_prev is None or self._z_prev is None:
            self._v_hat, self._t_prev, self._z_prev = v.copy(), time_s, z
            self._elapsed_s = 0.0
            return self.estimate_m_s2
        dt = time_s - self._t_prev
        if not dt > 0.0:
            return self.estimate_m_s2
        # achieved thrust over the interval: first-order lag toward the command, averaged
        t0 = self._thrust_n
        t_cmd = t0 if self._thrust_cmd_n is None else self._thrust_cmd_n
        tau = c.thrust_time_constant_s
        if tau > 0.0:
            decay = math.exp(-dt / tau)
            t_mean = t_cmd + (t0 - t_cmd) * tau / dt * (1.0 - decay)
            self._thrust_n = t_cmd + (t0 - t_cmd) * decay
        else:
            t_mean = self._thrust_n = t_cmd
        z_mean = 0.5 * (self._z_prev + z)
        f_model = (t_mean / c.mass_kg) * z_mean
        f_model[2] -= GRAVITY_M_S2
        f_model -= c.drag_per_mass_1_s * self._v_hat  # the airframe's own drag in still air
        v_pred = self._v_hat + (f_model + self.estimate_m_s2) * dt
        r = v - v_pred
        self._t_prev, self._z_prev = time_s, z
        if math.sqrt(float(r @ r)) > c.max_innovation_m_s:
            # a velocity jump no force made: an estimator reset; restart v^, keep d^
            self._v_hat = v.copy()
            self.resets += 1
            return self.estimate_m_s2
        # gains that put both discrete error poles at exp(-w dt), stable for any dt; from a
        # cold start the bandwidth starts at start_factor / (time since start) and decays to w
        # (a growing-memory start, as a Kalman filter with a large initial covariance)
        self._elapsed_s += dt
        w = max(c.bandwidth_rad_s, c.start_factor / self._elapsed_s)
        p = math.exp(-w * dt)
        self._v_hat = v_pred + (1.0 - p * p) * r
        d = self.estimate_m_s2 + ((1.0 - p) ** 2 / dt) * r
        n = math.sqrt(float(d @ d))
        if n > c.max_m_s2:
            d = d * (c.max_m_s2 / n) if n > 0.0 else np.zeros(3)
        self.estimate_m_s2 = d
        return d


def feedforward_accel(
    disturbance_enu_m_s2: np.ndarray, velocity_enu_m_s: np.ndarray, v_min_m_s: float
) -> np.ndarray:
    """The acceleration to add to a_d (m/s^2, ENU): -d^ normal to the velocity, and its
    along-track part only near hover, fading out from |v| = v_min to 2 v_min.

    In flight the speed ramp (eq. 14) owns the tangential channel with its own speed feedback;
    cancelling the along-track drag as well would add up to k_drag v of pitch-down during the
    ramp, which moves the target up the image (measured: 2 of 12 static targets lost off the
    top with full feed-forward). The normal part is what bends the path and makes the miss."""
    d = -np.asarray(disturbance_enu_m_s2, dtype=float)
    v = np.asarray(velocity_enu_m_s, dtype=float)
    speed = math.sqrt(float(v @ v))
    keep_tangential = min(max(2.0 - speed / v_min_m_s, 0.0), 1.0) if v_min_m_s > 0.0 else 0.0
    if keep_tangential >= 1.0 or speed < 1e-9:
        return d
    u = v / speed
    tangential = float(d @ u) * u
    return d - (1.0 - keep_tangential) * tangential
