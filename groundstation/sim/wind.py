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
from .physics import (
    JET_DECAY_B,
    JET_SPREAD_S,
    W_A,
    W_B,
    W_DIA,
    W_JET,
    W_MEAN,
    W_REF,
    W_SIGMA,
    W_SIZE,
    W_SOURCE,
    gust_step,
    jet_factor,
    wind_at,
)

__all__ = ["JET_DECAY_B", "JET_SPREAD_S", "VERTICAL_GUST_RATIO", "Wind", "jet_profile"]

VERTICAL_GUST_RATIO = 0.3
_BLOCK = 256  # standard normals drawn per call


def jet_profile(spec: WindSpec, p: tuple[float, float, float], on_axis: bool = False) -> float:
    """U(x, r) / U_0 of the fan jet at ``p`` (m, ENU), or with ``on_axis`` U_c(x) / U_0 at
    p's distance along the axis; 0 behind the fan or without a mean
    (:func:`.physics.jet_factor`)."""
    m, s = spec.mean_m_s, spec.jet_source_m
    return jet_factor(
        float(m[0]),
        float(m[1]),
        float(m[2]),
        float(s[0]),
        float(s[1]),
        float(s[2]),
        float(spec.jet_diameter_m),
        float(p[0]),
        float(p[1]),
        float(p[2]),
        bool(on_axis),
    )


class Wind:
    """``at(p)``: the wind (m/s, ENU) at a point now; ``step(dt)`` advances the gusts. The
    state (mean + gust now, the gust) is the array :attr:`x`, the constants :attr:`params`
    (:mod:`.physics`' W_* layout); the gusts' standard normals come from :meth:`normals`."""

    def __init__(
        self,
        spec: WindSpec,
        rng: np.random.Generator,
        reference_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.spec = spec
        self._rng = rng
        g = spec.gust_m_s
        self._sigma = (g, g, VERTICAL_GUST_RATIO * g)
        self._jet = spec.model == "jet"
        self.uniform = not self._jet  # the same wind at every point
        self.gusty = g > 0.0  # step() changes it
        self._ref_profile = jet_profile(spec, reference_m, on_axis=True) if self._jet else 1.0
        if self._jet and not self._ref_profile > 0.0:
            raise ValueError("the fan jet does not reach the reference point")
        c = np.zeros(W_SIZE)
        c[W_MEAN : W_MEAN + 3] = spec.mean_m_s
        c[W_SIGMA : W_SIGMA + 3] = self._sigma
        c[W_JET] = 1.0 if self._jet else 0.0
        c[W_REF] = self._ref_profile
        c[W_SOURCE : W_SOURCE + 3] = spec.jet_source_m
        c[W_DIA] = spec.jet_diameter_m
        self.params = c
        self.x = np.zeros(6)
        self.x[0:3] = spec.mean_m_s  # mean + gust at the reference point
        if g > 0.0:
            # start in the stationary distribution, not at zero
            m = spec.mean_m_s
            gust = [s * float(n) for s, n in zip(self._sigma, rng.standard_normal(3), strict=True)]
            self.x[3:6] = gust
            self.x[0:3] = (m[0] + gust[0], m[1] + gust[1], m[2] + gust[2])
        # the gusts' draws, the stream continued a block at a time (the sequence does not
        # depend on the block)
        self._normals = np.zeros((0, 3))
        self._next = 0  # the row of _normals the next step uses
        self._dt_s = -1.0

    @property
    def velocity_m_s(self) -> tuple[float, float, float]:
        """Mean + gust at the reference point (m/s ENU)."""
        return tuple(self.x[0:3].tolist())

    def scale_at(self, p) -> float:
        """The profile factor at ``p``: 1 for uniform wind, U(p) / U(reference) for the jet."""
        if not self._jet:
            return 1.0
        return jet_profile(self.spec, (float(p[0]), float(p[1]), float(p[2]))) / self._ref_profile

    def at(self, p) -> tuple[float, float, float]:
        """The wind now at ``p`` (m, ENU)."""
        if not self._jet:
            return self.velocity_m_s
        return wind_at(self.x, self.params, float(p[0]), float(p[1]), float(p[2]))

    def mean_at(self, p) -> tuple[float, float, float]:
        """The mean wind (no gust) at ``p``."""
        f = self.scale_at(p)
        m = self.spec.mean_m_s
        return (f * m[0], f * m[1], f * m[2])

    def prepare(self, dt: float, n: int) -> tuple[np.ndarray, int]:
        """Make ready ``n`` gust steps of ``dt`` (s): the factors for the step size, and
        standard normals for ``n`` steps from the returned row of the returned array (call
        :meth:`used` with the steps taken)."""
        if dt != self._dt_s:  # the factors, once per step size
            self._dt_s = dt
            a = math.exp(-dt / self.spec.gust_time_constant_s)
            self.params[W_A], self.params[W_B] = a, math.sqrt(1.0 - a * a)
        i = self._next
        if i + n > len(self._normals):
            more = self._rng.standard_normal((max(_BLOCK, n), 3))
            self._normals = np.concatenate((self._normals[i:], more))
            self._next = i = 0
        return self._normals, i

    def used(self, n: int) -> None:
        """``n`` of the prepared steps were taken."""
        self._next += n

    def step(self, dt: float) -> None:
        if not self.gusty:
            return
        normals, i = self.prepare(dt, 1)
        gust_step(self.x, self.params, normals[i, 0], normals[i, 1], normals[i, 2])
        self._next = i + 1
