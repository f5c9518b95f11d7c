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
for 0.05 m/s, w = 2 1/s, 100 Hz). A GNSS-aided estimate's error is correlated instead (0.1-0.2
m/s over about 1 s): its changes are about white at the observer's frequencies, and d^'s
standard deviation grows about as w (0.10 m/s^2 at w = 2 1/s for 0.15 m/s, 0.05 at 1); it is
flown, as -d^ normal to the velocity. Using the measured attitude means a manoeuvre, which the
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
from ..jit import kernel


@dataclass(frozen=True, slots=True)
class DisturbanceObserverConfig:
    """Observer settings: ``bandwidth_rad_s`` w (0 disables: d^ = 0), the motors' thrust lag
    (s), the clamp on |d^| (m/s^2), the velocity innovation treated as a reset (m/s), the
    cold-start factor (see the module doc) and the airframe's linear drag per unit mass
    (1/s, PX4 EKF2_MCOEF's rotor-drag model: -c times the velocity's part in the rotor plane)
    counted in the model, so that d^ is what the *wind* adds, not the airframe's own drag,
    which turns with the velocity and the thrust axis."""

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


_F64 = np.dtype(np.float64)


def _finite3(x) -> tuple[float, float, float] | None:
    """Three finite floats from a 3-vector (ndarray of shape (3,) or sequence), else None."""
    if type(x) is np.ndarray and x.dtype == _F64 and x.shape == (3,):  # the loop's: floats
        x0, x1, x2 = x.tolist()
        if math.isfinite(x0) and math.isfinite(x1) and math.isfinite(x2):
            return x0, x1, x2
        return None
    if isinstance(x, np.ndarray):
        if x.shape != (3,):
            return None
        x0, x1, x2 = x.tolist()
    else:
        try:
            x0, x1, x2 = x
        except (TypeError, ValueError):
            return None
    try:
        x0, x1, x2 = float(x0), float(x1), float(x2)
    except (TypeError, ValueError):
        return None
    if not (math.isfinite(x0) and math.isfinite(x1) and math.isfinite(x2)):
        return None
    return x0, x1, x2


class DisturbanceObserver:
    """Call :meth:`update` once per control tick with the state the loop was given, then
    :meth:`commanded` with the normalised thrust it sends; :attr:`estimate_m_s2` is d^ (ENU).

    The arithmetic is in floats, component by component (numpy's per-call cost on 3-vectors
    is several times the arithmetic's); every operation is the one the vector form does, in
    the same order, so the result is the same to the bit."""

    def __init__(self, config: DisturbanceObserverConfig) -> None:
        self.config = config
        self._d = (0.0, 0.0, 0.0)  # d^ as floats (estimate_m_s2 is its array)
        self._v_hat: tuple[float, float, float] | None = None
        self._z_prev: tuple[float, float, float] | None = None
        self._t_prev: float | None = None
        self._elapsed_s = 0.0
        self._thrust_n = config.mass_kg * GRAVITY_M_S2  # modelled achieved thrust
        self._thrust_cmd_n: float | None = None  # in force since the previous update
        self.resets = 0

    @property
    def estimate_m_s2(self) -> np.ndarray:
        """d^ (m/s^2, ENU), a new array."""
        return np.array(self._d)

    @property
    def estimate_floats(self) -> tuple[float, float, float]:
        """d^ (m/s^2, ENU) as three floats: :attr:`estimate_m_s2`'s values."""
        return self._d

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
            self._d = (0.0, 0.0, 0.0)
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
        v = _finite3(velocity_enu_m_s)
        z = _finite3(thrust_axis_enu)
        if v is not None and z is not None:
            self.update_floats(time_s, v, z)
        return np.array(self._d)

    def update_floats(
        self,
        time_s: float,
        velocity_enu_m_s: tuple[float, float, float],
        thrust_axis_enu: tuple[float, float, float],
    ) -> tuple[float, float, float]:
        """:meth:`update` with finite floats (the loop's own; not checked again); returns d^
        as :attr:`estimate_floats`."""
        v = velocity_enu_m_s
        z0, z1, z2 = thrust_axis_enu
        if not math.isfinite(time_s):
            return self._d
        zn = math.sqrt(z0 * z0 + z1 * z1 + z2 * z2)
        if not zn > 0.5:
            return self._d
        z = (z0 / zn, z1 / zn, z2 / zn)
        c = self.config
        if not c.bandwidth_rad_s > 0.0:
            self._t_prev, self._z_prev = time_s, z
            return self._d
        if self._v_hat is None or self._t_prev is None or self._z_prev is None:
            self._v_hat, self._t_prev, self._z_prev = v, time_s, z
            self._elapsed_s = 0.0
            return self._d
        dt = time_s - self._t_prev
        if not dt > 0.0:
            return self._d
        t0 = self._thrust_n
        t_cmd = t0 if self._thrust_cmd_n is None else self._thrust_cmd_n
        zp = self._z_prev
        self._t_prev, self._z_prev = time_s, z
        out = observer_step(
            dt,
            t0,
            t_cmd,
            c.thrust_time_constant_s,
            c.mass_kg,
            c.drag_per_mass_1_s,
            *zp,
            *z,
            *self._v_hat,
            *self._d,
            *v,
            c.max_innovation_m_s,
            c.bandwidth_rad_s,
            c.start_factor,
            self._elapsed_s,
            c.max_m_s2,
            2.0,
        )
        self._thrust_n = out[0]
        if out[1] < 0.0:
            # a velocity jump no force made: an estimator reset; restart v^, keep d^
            self._v_hat = v
            self.resets += 1
            return self._d
        self._elapsed_s = out[1]
        self._v_hat = (out[2], out[3], out[4])
        self._d = d = (out[5], out[6], out[7])
        return d


@kernel("UniTuple(float64, 8)(" + ", ".join(["float64"] * 27) + ")")
def observer_step(
    dt: float,
    thrust_n: float,
    thrust_cmd_n: float,
    tau: float,
    mass_kg: float,
    kd: float,
    zp0: float,
    zp1: float,
    zp2: float,
    z0: float,
    z1: float,
    z2: float,
    h0: float,
    h1: float,
    h2: float,
    e0: float,
    e1: float,
    e2: float,
    v0: float,
    v1: float,
    v2: float,
    max_innovation: float,
    bandwidth: float,
    start_factor: float,
    elapsed_s: float,
    max_m_s2: float,
    two: float,
) -> tuple[float, float, float, float, float, float, float, float]:
    """One step of the observer over ``dt`` (s) (compiled; see the module doc): from the
    modelled thrust (N) and its command, the thrust axis at the previous and this update
    (zp, z: unit, ENU), v^ (h), d^ (e) and the measured velocity (v). Returns the modelled
    thrust after the step, the time since the start (negative: a velocity jump larger than
    ``max_innovation``, an estimator reset: nothing else is valid), v^ and d^.

    ``two`` is 2.0, the exponent of (1 - p)^2, passed in so that the compiled code calls the C
    library's pow as Python does: a literal 2 is compiled to x * x, which rounds differently
    from pow in about 1 case in 1000."""
    # achieved thrust over the interval: first-order lag toward the command, averaged
    t0 = thrust_n
    t_cmd = thrust_cmd_n
    if tau > 0.0:
        decay = math.exp(-dt / tau)
        t_mean = t_cmd + (t0 - t_cmd) * tau / dt * (1.0 - decay)
        thrust_n = t_cmd + (t0 - t_cmd) * decay
    else:
        t_mean = thrust_n = t_cmd
    # f_model = (T / m) z_mean - g e_z - c (v^ - (v^ . z_mean) z_mean): the airframe's own
    # drag in still air, in the rotor plane (EKF2_MCOEF's rotor-drag model)
    k = t_mean / mass_kg
    m0, m1, m2 = 0.5 * (zp0 + z0), 0.5 * (zp1 + z1), 0.5 * (zp2 + z2)
    hz = h0 * m0 + h1 * m1 + h2 * m2
    f0 = k * m0 - kd * (h0 - hz * m0)
    f1 = k * m1 - kd * (h1 - hz * m1)
    f2 = (k * m2 - GRAVITY_M_S2) - kd * (h2 - hz * m2)
    p0, p1, p2 = h0 + (f0 + e0) * dt, h1 + (f1 + e1) * dt, h2 + (f2 + e2) * dt  # v_pred
    r0, r1, r2 = v0 - p0, v1 - p1, v2 - p2
    if math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) > max_innovation:
        return thrust_n, -1.0, h0, h1, h2, e0, e1, e2
    # gains that put both discrete error poles at exp(-w dt), stable for any dt; from a
    # cold start the bandwidth starts at start_factor / (time since start) and decays to w
    # (a growing-memory start, as a Kalman filter with a large initial covariance)
    elapsed_s += dt
    w = max(bandwidth, start_factor / elapsed_s)
    p = math.exp(-w * dt)
    g = 1.0 - p * p
    vh0, vh1, vh2 = p0 + g * r0, p1 + g * r1, p2 + g * r2
    g = (1.0 - p) ** two / dt
    d0, d1, d2 = e0 + g * r0, e1 + g * r1, e2 + g * r2
    n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if n > max_m_s2:
        if n > 0.0:
            g = max_m_s2 / n
            d0, d1, d2 = d0 * g, d1 * g, d2 * g
        else:
            d0 = d1 = d2 = 0.0
    return thrust_n, elapsed_s, vh0, vh1, vh2, d0, d1, d2


def feedforward_accel(
    disturbance_enu_m_s2: np.ndarray, velocity_enu_m_s: np.ndarray, v_min_m_s: float
) -> np.ndarray:
    """The acceleration to add to a_d (m/s^2, ENU): -d^ normal to the velocity, and its
    along-track part only near hover, fading out from |v| = v_min to 2 v_min
    (:func:`feedforward_floats`)."""
    d0, d1, d2 = _floats(disturbance_enu_m_s2)
    v0, v1, v2 = _floats(velocity_enu_m_s)
    return np.array(feedforward_floats(d0, d1, d2, v0, v1, v2, float(v_min_m_s)))


@kernel("UniTuple(float64, 3)(float64, float64, float64, float64, float64, float64, float64)")
def feedforward_floats(
    d0: float, d1: float, d2: float, v0: float, v1: float, v2: float, v_min_m_s: float
) -> tuple[float, float, float]:
    """:func:`feedforward_accel` of d^ = (d0, d1, d2) and v = (v0, v1, v2) in floats
    (compiled).

    In flight the speed ramp (eq. 14) owns the tangential channel with its own speed feedback;
    cancelling the along-track drag as well would add up to k_drag v of pitch-down during the
    ramp, which moves the target up the image (measured: 2 of 12 static targets lost off the
    top with full feed-forward). The normal part is what bends the path and makes the miss."""
    d0, d1, d2 = -d0, -d1, -d2
    speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    keep_tangential = min(max(2.0 - speed / v_min_m_s, 0.0), 1.0) if v_min_m_s > 0.0 else 0.0
    if keep_tangential >= 1.0 or speed < 1e-9:
        return d0, d1, d2
    u0, u1, u2 = v0 / speed, v1 / speed, v2 / speed
    a = d0 * u0 + d1 * u1 + d2 * u2
    g = 1.0 - keep_tangential
    return d0 - g * (a * u0), d1 - g * (a * u1), d2 - g * (a * u2)


def _floats(x) -> list[float]:
    """A 3-vector (ndarray or sequence) as floats."""
    return x.tolist() if isinstance(x, np.ndarray) else [float(c) for c in x]
