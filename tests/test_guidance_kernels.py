"""The guidance law's compiled kernels (onboard/control/guidance.py) give their Python
source's results bit for bit on seeded random inputs, non-finite ones included, and the
ported ``hypot2`` gives CPython's ``math.hypot`` to the bit (numba's own hypot is libm's)."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from onboard.control import guidance as G  # noqa: N812

pytestmark = pytest.mark.skipif(
    not hasattr(G.png_floats, "py_func"), reason="PEREGRINE_JIT=0: no compiled kernels"
)

N = 3000


def _bits(out) -> tuple:
    vals = out if isinstance(out, tuple) else (out,)
    return tuple(b"nan" if math.isnan(v) else struct.pack("<d", float(v)) for v in vals)


def _floats(rng: np.random.Generator, n: int, special: float = 0.045) -> list[float]:
    """n floats of mixed scales with the odd zero, inf and NaN (``special``: their share)."""
    x = rng.standard_normal(n) * rng.choice([1e-12, 1e-3, 1.0, 10.0, 1e3], n)
    u = rng.random(n) / max(special, 1e-9) * 0.045
    x[u < 0.03] = 0.0
    x[(u >= 0.03) & (u < 0.04)] = math.nan
    x[(u >= 0.04) & (u < 0.045)] = -math.inf
    return x.tolist()


def _unit(rng: np.random.Generator) -> list[float]:
    v = rng.standard_normal(3)
    return (v / np.linalg.norm(v)).tolist()


@pytest.mark.parametrize("scale", [1.0, 1e-3, 1e3, 1e-150, 1e150, 1e-300])
def test_hypot2_is_cpythons_hypot_to_the_bit(scale):
    rng = np.random.default_rng(1700)
    n = 100_000
    x = rng.standard_normal(n) * scale
    y = x * rng.choice([1.0, 1e-8, 1e8, 0.0, -1.0], n) + rng.standard_normal(n) * scale
    bad = [
        (a, b)
        for a, b in zip(x.tolist(), y.tolist(), strict=True)
        if _bits(G.hypot2(a, b)) != _bits(math.hypot(a, b))
    ]
    assert not bad, bad[:5]
    for a, b in zip(x[:3000].tolist(), y[:3000].tolist(), strict=True):  # the source, too
        assert _bits(G.hypot2.py_func(a, b)) == _bits(math.hypot(a, b))


def test_hypot2_special_values():
    inf, nan = math.inf, math.nan
    cases = [(inf, nan), (nan, -inf), (nan, 1.0), (0.0, -0.0), (-3.0, 4.0), (1e308, 1e308)]
    cases += [(5e-324, 0.0), (2.5e-308, 3e-308), (1.0, 1e-300)]
    for a, b in cases:
        assert _bits(G.hypot2(a, b)) == _bits(math.hypot(a, b)), (a, b)


def test_direction_angles_match_the_formula_with_math_hypot():
    rng = np.random.default_rng(1701)
    for _ in range(20_000):
        x, y, z = _floats(rng, 3, special=0.01)
        want = (math.atan2(z, math.hypot(x, y)), math.atan2(x, y))
        assert _bits(G.direction_angles(np.array((x, y, z)))) == _bits(want)


def _png_args(rng: np.random.Generator, gains: np.ndarray) -> tuple:
    l0, l1, l2 = _unit(rng)
    ax = _unit(rng)
    v = (np.array(_unit(rng)) * rng.choice([0.0, 0.3, 3.0, 12.0])).tolist()
    if rng.random() < 0.1:
        v[rng.integers(3)] = _floats(rng, 1, special=1.0)[0]  # a non-finite velocity
    top, bottom = (0.64, -0.64) if rng.random() < 0.8 else (math.nan, math.nan)
    has_vt = bool(rng.random() < 0.5)
    vt = _floats(rng, 3, special=0.02)
    return (
        float(rng.choice([0.01, 0.005, 0.0123])),
        l0, l1, l2,
        math.atan2(l2, math.hypot(l0, l1)),
        *(rng.standard_normal(2) * 0.01).tolist(),
        *v,
        *ax,
        top,
        bottom,
        float(rng.choice([math.nan, 10.0, 55.0, 300.0])),
        has_vt,
        *vt,
        float(rng.choice([math.nan, 0.0, 4.0])),
        *(rng.standard_normal(3) * rng.choice([0.0, 1.0, 3.0])).tolist(),
        gains,
    )  # fmt: skip


def test_png_kernel_matches_its_source():
    rng = np.random.default_rng(1702)
    for i in range(N):
        gains = G.Gains().packed
        if i % 3 == 1:  # the FOV guard, pursuit and midcourse terms switched off in turn
            gains = gains.copy()
            gains[rng.choice([5, 7, 11])] = 0.0
        args = _png_args(rng, gains)
        assert _bits(G.png_floats(*args)) == _bits(G.png_floats.py_func(*args)), args


def test_png_kernel_flies_each_branch():
    """The seeded inputs reach the hover start, the FOV guard, the pursuit bias and the
    midcourse term (so the comparison above covers them)."""
    rng = np.random.default_rng(1702)
    seen = set()
    gains = G.Gains().packed
    for _ in range(N):
        args = _png_args(rng, gains)
        a0, a1, a2, _, _, hovering = G.png_floats(*args)
        seen.add("hover" if hovering else "fly")
        q_y = args[4]
        ax0, ax1, ax2, top, bottom, range_m = args[10:16]
        if G.pursuit_floats(gains[7], gains[8], top, bottom, ax0, ax1, ax2, q_y) > 0.0:
            seen.add("pursuit")
        if G.midcourse_floats(range_m, gains[5], gains[6]) > 0.0:
            seen.add("midcourse")
        if G.fov_guard_floats(a0, a1, a2, top, ax0, ax1, q_y, gains[11], gains[2])[0] == 0.0:
            seen.add("guard idle")
    assert {"hover", "fly", "pursuit", "midcourse", "guard idle"} <= seen, seen


def test_guard_terms_match_their_source():
    rng = np.random.default_rng(1703)
    for _ in range(N):
        f = _floats(rng, 12)
        ax = _unit(rng)
        cases = [
            (G.fov_guard_floats, (*f[:3], 0.64, ax[0], ax[1], f[3], 0.14, 5.0)),
            (G.fov_guard_floats, (*f[:3], f[4], f[5], f[6], f[7], float(f[8] > 0), 5.0)),
            (G.edge_margin_floats, (0.64, -0.64, *ax, f[9])),
            (G.pursuit_floats, (0.26, 4.0, 0.64, -0.64, *ax, f[10])),
            (G.midcourse_floats, (f[11], 1.5, 40.0)),
            (G.zem_floats, (*f[:3], bool(f[4] > 0), *f[5:8], f[8], *ax, 1.5)),
            (G.ramped_speed_floats, (f[0], 1.0, 12.0, 2.0, 0.01)),
            (G.saturate3, (*f[:3], 5.0)),
            (G.min_pitch_rad, (f[0], 0.64, 0.14)),
        ]
        for k, args in cases:
            assert _bits(k(*args)) == _bits(k.py_func(*args)), (k.__name__, args)
