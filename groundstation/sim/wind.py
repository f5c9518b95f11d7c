"""Wind, evaluated at each body's position (vehicle and balloon): a seeded gust process times a
spatial profile.

Gusts (both models): each axis a first-order Gauss-Markov (Ornstein-Uhlenbeck) process of
standard deviation ``gust_m_s`` (vertical at 30 %) and correlation time
``gust_time_constant_s``: the first-order form of the Dryden spectrum (MIL-F-8785C; MIL-HDBK-
1797 §3.7), whose time constant is the turbulence length scale over the airspeed. One gust
vector for the whole scene (the scene is small against the length scales), started in its
stationary distribution. The defaults of the outdoor scenarios follow MIL-F-8785C's low-
altitude model for light turbulence at h = 5 m with a 3 m/s wind at 6 m (W20): sigma_u =
0.1 W20 / (0.177 + 0.000823 h[ft])^0.4 = 0.58 m/s, L_u = h / (0.177 + 0.000823 h)^1.2 = 37 m,
so L_u / V = 5 s at the interceptor's 7 m/s airspeed. (The same model gives sigma_w / sigma_u
about 0.5 at 5 m; the vertical share here stays at the earlier 30 %.)

Models (``wind.model``):

- ``uniform``: ``mean_m_s`` + gust everywhere (outdoor).
- ``jet``: a fan's round turbulent jet (indoor, the paper's §V-B fans). The wind at p is
  ``f(p) (mean_m_s + gust)``: the direction is the jet axis (``mean_m_s``'s direction through
  ``jet_source_m``), the gusts keep a constant turbulence intensity, and ``mean_m_s`` is the
  centreline speed at the reference point's distance from the fan (the balloon's rest
  position: the shipped scenarios put it on the axis), measured there as the paper did ("wind
  speed at the balloon's location was measured using an anemometer when the balloon was
  stationary"). f(p) = U(x, r) / U_c(x_ref) with x the distance along the axis from the fan,
  r from the axis, D = ``jet_diameter_m``:

      U(x, r) = U_c(x) exp(-ln 2 (r / r_half(x))^2),  x > 0;   0 behind the fan
      U_c(x) = U_0 min(1, B D / x),  r_half(x) = max(D / 2, S x)

  the self-similar far field of a round jet with B = 5.8 (centreline decay) and S = 0.094
  (spreading rate) from Hussein, Capp & George, J. Fluid Mech. 258 (1994), as tabulated in
  Pope, *Turbulent Flows* (2000) §5.1, Table 5.1; the potential core (top hat of the fan's
  width) ends where B D / x = 1, x = 5.8 D. The radial entrainment velocity (a few % of U_c) is
  neglected.
"""

from __future__ import annotations

import math

import numpy as np

from ..scenario import WindSpec
from .estimate import Normals

JET_DECAY_B = 5.8  # U_c / U_0 = B D / x (Hussein et al. 1994; Pope Table 5.1)
JET_SPREAD_S = 0.094  # r_1/2 = S x
VERTICAL_GUST_RATIO = 0.3
_LN2 = math.log(2.0)


def jet_profile(spec: WindSpec, p: tuple[float, float, float], on_axis: bool = False) -> float:
    """U(x, r) / U_0 of the fan jet at ``p`` (m, ENU), or with ``on_axis`` U_c(x) / U_0 at
    p's distance along the axis; 0 behind the fan or without a mean."""
    m = spec.mean_m_s
    speed = math.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
    if speed <= 0.0:
        return 0.0
    s = spec.jet_source_m
    d = (p[0] - s[0], p[1] - s[1], p[2] - s[2])
    x = (d[0] * m[0] + d[1] * m[1] + d[2] * m[2]) / speed
    if x <= 0.0:
        return 0.0
    if on_axis:
        return min(1.0, JET_DECAY_B * spec.jet_diameter_m / x)
    r2 = max(d[0] * d[0] + d[1] * d[1] + d[2] * d[2] - x * x, 0.0)
    dia = spec.jet_diameter_m
    r_half = max(0.5 * dia, JET_SPREAD_S * x)
    return min(1.0, JET_DECAY_B * dia / x) * math.exp(-_LN2 * r2 / (r_half * r_half))


class Wind:
    """``at(p)``: the wind (m/s, ENU) at a point now; ``step(dt)`` advances the gusts."""

    def __init__(
        self,
        spec: WindSpec,
        rng: np.random.Generator,
        reference_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.spec = spec
        self._rng = rng
        self._gust = [0.0, 0.0, 0.0]
        g = spec.gust_m_s
        self._sigma = (g, g, VERTICAL_GUST_RATIO * g)
        self._jet = spec.model == "jet"
        self.uniform = not self._jet  # the same wind at every point
        self.gusty = g > 0.0  # step() changes it
        self._ref_profile = jet_profile(spec, reference_m, on_axis=True) if self._jet else 1.0
        if self._jet and not self._ref_profile > 0.0:
            raise ValueError("the fan jet does not reach the reference point")
        self.velocity_m_s = tuple(spec.mean_m_s)  # mean + gust at the reference point
        if g > 0.0:
            # start in the stationary distribution, not at zero
            self._gust = [
                s * float(n) for s, n in zip(self._sigma, rng.standard_normal(3), strict=True)
            ]
            self._update_total()
        self._normals = Normals(rng, 3)  # the gusts' draws, the stream continued
        self._dt_s = -1.0
        self._a = self._b = 0.0

    def _update_total(self) -> None:
        m = self.spec.mean_m_s
        self.velocity_m_s = (m[0] + self._gust[0], m[1] + self._gust[1], m[2] + self._gust[2])

    def scale_at(self, p) -> float:
        """The profile factor at ``p``: 1 for uniform wind, U(p) / U(reference) for the jet."""
        if not self._jet:
            return 1.0
        return jet_profile(self.spec, (float(p[0]), float(p[1]), float(p[2]))) / self._ref_profile

    def at(self, p) -> tuple[float, float, float]:
        """The wind now at ``p`` (m, ENU)."""
        w = self.velocity_m_s
        if not self._jet:
            return w
        f = self.scale_at(p)
        return (f * w[0], f * w[1], f * w[2])

    def mean_at(self, p) -> tuple[float, float, float]:
        """The mean wind (no gust) at ``p``."""
        f = self.scale_at(p)
        m = self.spec.mean_m_s
        return (f * m[0], f * m[1], f * m[2])

    def step(self, dt: float) -> None:
        if not self.gusty:
            return
        if dt != self._dt_s:  # the factors, once per step size
            self._dt_s = dt
            self._a = math.exp(-dt / self.spec.gust_time_constant_s)
            self._b = math.sqrt(1.0 - self._a * self._a)
        a, b = self._a, self._b
        n = self._normals.next()
        g, s = self._gust, self._sigma
        self._gust = [
            a * g[0] + b * s[0] * n[0],
            a * g[1] + b * s[1] * n[1],
            a * g[2] + b * s[2] * n[2],
        ]
        self._update_total()
