"""The random processes the simulator's sensor errors are made of: standard normals drawn a
block at a time, the first-order Gauss-Markov process (stepped exactly for any dt) and the
random walk, as kernels over arrays and as small objects (the state-estimate model in
:mod:`.estimate` steps the same kernels over its own arrays)."""

from __future__ import annotations

import math

import numpy as np

from onboard.jit import kernel

BLOCK = 256  # normals drawn per call of a stream


class Normals:
    """Standard normal vectors of one stream, drawn a block at a time (one call per 256
    samples instead of one each: the stream's sequence does not depend on the block)."""

    def __init__(self, rng: np.random.Generator, dim: int, block: int = BLOCK) -> None:
        self._rng, self._dim, self._block = rng, dim, block
        self._buf = np.empty((0, dim))
        self._i = 0

    def row(self) -> np.ndarray:
        """The next vector (a row of the block: read it before the block is redrawn)."""
        i = self._i
        if i >= self._buf.shape[0]:
            self._buf = self._rng.standard_normal((self._block, self._dim))
            i = 0
        self._i = i + 1
        return self._buf[i]

    def next(self) -> list[float]:
        """The next vector as floats."""
        return self.row().tolist()


@kernel("UniTuple(f8, 2)(f8, f8, f8)")
def gauss_markov_factors(dt_s: float, tau_s: float, sigma: float) -> tuple[float, float]:
    """The exact step of a first-order Gauss-Markov process over ``dt_s``: a = exp(-dt/tau)
    and b = sigma sqrt(1 - a^2), x <- a x + b n."""
    a = math.exp(-dt_s / tau_s)
    return a, sigma * math.sqrt(1.0 - a * a)


@kernel("void(f8[::1], f8, f8, f8[::1])")
def gauss_markov_step(x: np.ndarray, a: float, b: float, n: np.ndarray) -> None:
    """x <- a x + b n in place (:func:`gauss_markov_factors`; n standard normal)."""
    for i in range(x.shape[0]):
        x[i] = a * x[i] + b * n[i]


@kernel("void(f8[::1], f8, f8[::1])")
def random_walk_step(x: np.ndarray, s: float, n: np.ndarray) -> None:
    """x <- x + s n in place (s = walk x sqrt(dt); n standard normal)."""
    for i in range(x.shape[0]):
        x[i] = x[i] + s * n[i]


class GaussMarkov:
    """First-order Gauss-Markov process per component, x' = -x / tau + w, stationary standard
    deviation ``sigma``; started in its stationary distribution and stepped exactly for any
    dt (:func:`gauss_markov_factors`, :func:`gauss_markov_step`, the kernels the state
    estimate model's steps call too). :attr:`x` is the state (an array, updated in place)."""

    def __init__(self, sigma: float, tau_s: float, dim: int, rng: np.random.Generator) -> None:
        self.sigma = float(sigma)
        self.tau_s = float(tau_s)
        self._normals = Normals(rng, dim)
        self.x = self.sigma * self._normals.row()
        self._dt_s = -1.0
        self._a = self._b = 0.0

    @property
    def value(self) -> np.ndarray:
        return self.x.copy()

    def step(self, dt_s: float) -> np.ndarray:
        if dt_s != self._dt_s:  # the factors, once per step size
            self._dt_s = dt_s
            self._a, self._b = gauss_markov_factors(dt_s, self.tau_s, self.sigma)
        gauss_markov_step(self.x, self._a, self._b, self._normals.row())
        return self.x


class RandomWalk:
    """A bias: N(0, ``initial``) per component at the start, then a random walk of
    ``walk_per_sqrt_s`` (its standard deviation grows as walk x sqrt(t))
    (:func:`random_walk_step`). :attr:`x` as :class:`GaussMarkov`'s."""

    def __init__(
        self, initial: float, walk_per_sqrt_s: float, dim: int, rng: np.random.Generator
    ) -> None:
        self.walk = float(walk_per_sqrt_s)
        self._normals = Normals(rng, dim)
        self.x = float(initial) * self._normals.row()

    @property
    def value(self) -> np.ndarray:
        return self.x.copy()

    def step(self, dt_s: float) -> np.ndarray:
        random_walk_step(self.x, self.walk * math.sqrt(dt_s), self._normals.row())
        return self.x
