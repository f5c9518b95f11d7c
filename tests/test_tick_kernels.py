"""The control tick's compiled kernels (onboard/jit.py) give their Python source's results bit
for bit on seeded random inputs, non-finite ones included (the tick's guard relies on NaN
reaching the command)."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from onboard.control.attitude import attitude_floats
from onboard.control.disturbance import feedforward_floats, observer_step
from onboard.control.guidance import normal_floats

pytestmark = pytest.mark.skipif(
    not hasattr(attitude_floats, "py_func"), reason="PEREGRINE_JIT=0: no compiled kernels"
)

N = 3000


def _bits(out) -> tuple:
    vals = out if isinstance(out, tuple) else (out,)
    return tuple(struct.pack("<d", float(v)) if not math.isnan(v) else b"nan" for v in vals)


def _floats(rng: np.random.Generator, n: int) -> list[float]:
    """n floats of mixed scales with the odd zero, inf and NaN."""
    x = rng.standard_normal(n) * rng.choice([1e-12, 1e-3, 1.0, 10.0, 1e3], n)
    special = rng.random(n)
    x[special < 0.03] = 0.0
    x[(special >= 0.03) & (special < 0.04)] = math.nan
    x[(special >= 0.04) & (special < 0.045)] = math.inf
    return x.tolist()


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.standard_normal(4)
    w, x, y, z = (q / np.linalg.norm(q)).tolist()
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_attitude_kernel_matches_its_source():
    rng = np.random.default_rng(1601)
    for i in range(N):
        a = _floats(rng, 3)
        R = _rotation(rng)
        if i % 50 == 0:  # thrust along the body axis: the parallel / antiparallel branches
            a = (R[:, 2] * rng.choice([-30.0, 5.0]) - np.array([0.0, 0.0, 9.81])).tolist()
        if i % 97 == 0:
            R[rng.integers(3), rng.integers(3)] = math.nan
        args = (*a, R, *_floats(rng, 1), 8.0, float(rng.choice([0.0, 4.0])), 1.5, 44.1)
        assert _bits(attitude_floats(*args)) == _bits(attitude_floats.py_func(*args))


def test_observer_step_matches_its_source():
    rng = np.random.default_rng(1602)
    for _ in range(N):
        dt = float(rng.choice([0.01, 0.005, 0.0131, 1e-6]))
        tau = float(rng.choice([0.0, 0.03]))
        zp = _rotation(rng)[:, 2].tolist()
        z = _rotation(rng)[:, 2].tolist()
        h, e, v = (rng.standard_normal(3).tolist() for _ in range(3))
        args = (
            dt,
            float(rng.uniform(0, 40)),
            float(rng.uniform(0, 40)),
            tau,
            1.5,
            float(rng.choice([0.0, 0.17])),
            *zp,
            *z,
            *h,
            *e,
            *v,
            float(rng.choice([2.0, 0.5])),
            float(rng.choice([0.5, 2.0])),
            3.0,
            float(rng.uniform(0, 5)),
            float(rng.choice([0.5, 5.0])),
            2.0,
        )
        assert _bits(observer_step(*args)) == _bits(observer_step.py_func(*args))


def test_feedforward_and_normal_kernels_match_their_source():
    rng = np.random.default_rng(1603)
    for _ in range(N):
        d, v = _floats(rng, 3), _floats(rng, 3)
        v_min = float(rng.choice([0.0, 0.5, 3.0]))
        assert _bits(feedforward_floats(*d, *v, v_min)) == _bits(
            feedforward_floats.py_func(*d, *v, v_min)
        )
        assert _bits(normal_floats(*d, *v)) == _bits(normal_floats.py_func(*d, *v))


def test_a_nan_acceleration_reaches_the_thrust():
    """The tick's guard trips on a non-finite command: the kernel must not clamp NaN away."""
    R = np.eye(3)
    _, _, _, thrust = attitude_floats(math.nan, 0.0, 0.0, R, 0.0, 8.0, 4.0, 1.5, 44.1)
    assert math.isnan(thrust)
