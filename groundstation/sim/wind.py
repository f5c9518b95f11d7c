"""Wind: a mean vector plus seeded gusts, each axis a first-order Gauss-Markov process
(vertical gusts at 30 % of the horizontal strength)."""

from __future__ import annotations

import math

import numpy as np

from ..scenario import WindSpec


class Wind:
    def __init__(self, spec: WindSpec, rng: np.random.Generator) -> None:
        self.spec = spec
        self._rng = rng
        self._gust = [0.0, 0.0, 0.0]
        self._sigma = (spec.gust_m_s, spec.gust_m_s, 0.3 * spec.gust_m_s)
        self.velocity_m_s = tuple(spec.mean_m_s)
        if spec.gust_m_s > 0.0:
            # start in the stationary distribution, not at zero
            self._gust = [
                s * float(n) for s, n in zip(self._sigma, rng.standard_normal(3), strict=True)
            ]
            self._update_total()

    def _update_total(self) -> None:
        m = self.spec.mean_m_s
        self.velocity_m_s = (m[0] + self._gust[0], m[1] + self._gust[1], m[2] + self._gust[2])

    def step(self, dt: float) -> None:
        if self.spec.gust_m_s <= 0.0:
            return
        tau = self.spec.gust_time_constant_s
        a = math.exp(-dt / tau)
        b = math.sqrt(1.0 - a * a)
        n = self._rng.standard_normal(3)
        self._gust = [
            a * g + b * s * float(k) for g, s, k in zip(self._gust, self._sigma, n, strict=True)
        ]
        self._update_total()
