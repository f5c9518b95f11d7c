"""Wind, evaluated at each body's position (vehicle and light target): a mean, a turbulence
field that varies in space and time, and a spatial profile (docs/air.md).

Turbulence (both models): a frozen field of von Kármán turbulence carried by the mean wind
(Taylor's hypothesis), the same field for every body, so that two points near each other feel
correlated gusts and two far apart independent ones. The field is a sum of ``TURBULENCE_MODES``
random Fourier modes (Kraichnan, Phys. Fluids 13, 1970): wavenumbers drawn from the von
Kármán energy spectrum E(k) ~ (k l)^4 / (1 + (k l)^2)^(17/6) with l = 1.339 L, L the
longitudinal integral length scale (MIL-HDBK-1797 §3.7's von Kármán form; MIL-F-8785C), each
mode's amplitude across its wavenumber (a divergence-free field), then each axis scaled to the
standard deviation ``gust_m_s`` (vertical at ``VERTICAL_GUST_RATIO``) exactly over space. L is
``turbulence_length_m``, or where that is 0 ``gust_time_constant_s`` times the mean wind's
speed (at least 1 m/s): the time a gust takes to pass. The field is seeded by the sortie.

The defaults of the outdoor scenarios follow MIL-F-8785C's low-altitude model for light
turbulence at h = 5 m with a 3 m/s wind at 6 m (W20): sigma_u = 0.1 W20 / (0.177 + 0.000823
h[ft])^0.4 = 0.58 m/s, L_u = h / (0.177 + 0.000823 h)^1.2 = 37 m. (The same model gives
sigma_w / sigma_u about 0.5 at 5 m; the vertical share here stays at 30 %.)

Models (``wind.model``):

- ``uniform``: ``mean_m_s`` + turbulence everywhere (outdoor).
- ``jet``: a fan's round turbulent jet (indoor, the paper's §V-B fans). The wind at p is
  ``f(p) (mean_m_s + turbulence(p))``: the direction is the jet axis (``mean_m_s``'s
  direction through ``jet_source_m``), the turbulence keeps a constant intensity, and
  ``mean_m_s`` is the centreline speed at the reference point's distance from the fan (the
  balloon's rest position: the shipped scenarios put it on the axis), measured there as the
  paper did ("wind speed at the balloon's location was measured using an anemometer when the
  balloon was stationary"). f(p) = U(x, r) / U_c(x_ref) with x the distance along the axis
  from the fan, r from the axis, D = ``jet_diameter_m``:

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
    M_SIZE,
    W_DIA,
    W_JET,
    W_MEAN,
    W_NMODES,
    W_REF,
    W_SIGMA,
    W_SIZE,
    W_SOURCE,
    W_TIME,
    jet_factor,
    wind_at,
)

__all__ = [
    "JET_DECAY_B",
    "JET_SPREAD_S",
    "TURBULENCE_MODES",
    "VERTICAL_GUST_RATIO",
    "VON_KARMAN_SCALE",
    "Wind",
    "jet_profile",
    "turbulence_modes",
]

VERTICAL_GUST_RATIO = 0.3
TURBULENCE_MODES = 96
VON_KARMAN_SCALE = 1.339  # l = 1.339 L in the von Karman spectra (MIL-HDBK-1797)
_NO_MODES = np.zeros((0, M_SIZE))


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


def turbulence_modes(
    rng: np.random.Generator, length_m: float, n: int = TURBULENCE_MODES
) -> np.ndarray:
    """``n`` random Fourier modes (M_* rows: wavenumber rad/m, cosine and sine amplitudes) of
    isotropic von Kármán turbulence of longitudinal integral length ``length_m`` (m), each
    axis of unit variance over space. Wavenumbers by stratified sampling of the energy
    spectrum (one draw in each of n equal-probability bands), directions uniform, amplitudes
    across the wavenumber."""
    if not (math.isfinite(length_m) and length_m > 0.0):
        raise ValueError(f"turbulence length {length_m!r} m must be positive")
    ell = VON_KARMAN_SCALE * length_m
    x = np.geomspace(1e-4, 1e4, 8001)  # k l
    pdf = x**4 / (1.0 + x * x) ** (17.0 / 6.0)
    cdf = np.concatenate(([0.0], np.cumsum(0.5 * (pdf[1:] + pdf[:-1]) * np.diff(x))))
    cdf /= cdf[-1]
    u = (np.arange(n) + rng.uniform(size=n)) / n
    k = np.interp(u, cdf, x) / ell
    khat = rng.standard_normal((n, 3))
    khat /= np.linalg.norm(khat, axis=1, keepdims=True)
    amps = []
    for _ in range(2):  # cosine, sine: random directions across the wavenumber
        a = rng.standard_normal((n, 3))
        a -= np.sum(a * khat, axis=1, keepdims=True) * khat
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        amps.append(a)
    c, s = amps
    # each axis's variance over space is sum(c_i^2 + s_i^2) / 2: make it exactly 1
    var = 0.5 * np.sum(c * c + s * s, axis=0)
    c, s = c / np.sqrt(var), s / np.sqrt(var)
    return np.ascontiguousarray(np.hstack((khat * k[:, None], c, s)))


class Wind:
    """``at(p)``: the wind (m/s, ENU) at a point now; ``step(dt)`` advances time. The
    constants are the array :attr:`params` (:mod:`.physics`' W_* layout, the time now in it),
    the turbulence the array :attr:`modes` (M_* rows; none without gusts)."""

    def __init__(
        self,
        spec: WindSpec,
        rng: np.random.Generator,
        reference_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.spec = spec
        g = spec.gust_m_s
        self._sigma = (g, g, VERTICAL_GUST_RATIO * g)
        self._jet = spec.model == "jet"
        self.reference_m = tuple(float(c) for c in reference_m)
        self.uniform = not self._jet and g == 0.0  # the same wind at every point
        self.gusty = g > 0.0  # the wind changes in time
        self._ref_profile = jet_profile(spec, reference_m, on_axis=True) if self._jet else 1.0
        if self._jet and not self._ref_profile > 0.0:
            raise ValueError("the fan jet does not reach the reference point")
        mean_speed = math.sqrt(sum(c * c for c in spec.mean_m_s))
        self.length_m = spec.turbulence_length_m or spec.gust_time_constant_s * max(mean_speed, 1.0)
        self.modes = turbulence_modes(rng, self.length_m) if g > 0.0 else _NO_MODES
        c = np.zeros(W_SIZE)
        c[W_MEAN : W_MEAN + 3] = spec.mean_m_s
        c[W_SIGMA : W_SIGMA + 3] = self._sigma
        c[W_TIME] = 0.0
        c[W_NMODES] = len(self.modes)
        c[W_JET] = 1.0 if self._jet else 0.0
        c[W_REF] = self._ref_profile
        c[W_SOURCE : W_SOURCE + 3] = spec.jet_source_m
        c[W_DIA] = spec.jet_diameter_m
        self.params = c

    @property
    def time_s(self) -> float:
        return float(self.params[W_TIME])

    @property
    def velocity_m_s(self) -> tuple[float, float, float]:
        """Mean + turbulence at the reference point now (m/s ENU)."""
        return self.at(self.reference_m)

    def scale_at(self, p) -> float:
        """The profile factor at ``p``: 1 for uniform wind, U(p) / U(reference) for the jet."""
        if not self._jet:
            return 1.0
        return jet_profile(self.spec, (float(p[0]), float(p[1]), float(p[2]))) / self._ref_profile

    def at(self, p) -> tuple[float, float, float]:
        """The wind now at ``p`` (m, ENU)."""
        return wind_at(self.params, self.modes, float(p[0]), float(p[1]), float(p[2]))

    def mean_at(self, p) -> tuple[float, float, float]:
        """The mean wind (no turbulence) at ``p``."""
        f = self.scale_at(p)
        m = self.spec.mean_m_s
        return (f * m[0], f * m[1], f * m[2])

    def step(self, dt: float) -> None:
        """Advance the time by ``dt`` (s)."""
        self.params[W_TIME] += dt
