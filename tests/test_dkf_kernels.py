"""The DKF's numba kernels (onboard/estimation/dkf_kernels.py) equal their own Python source
bit for bit (``k.py_func``) on seeded random inputs, edge values included; with the JIT off (the
default outside campaigns: run with PEREGRINE_JIT=1) there is nothing compiled to compare."""

import copy
import math

import numpy as np
import pytest

from onboard import jit
from onboard.camera_model import CameraModel
from onboard.datatypes import Detection
from onboard.estimation import dkf as kernels

pytestmark = pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing compiled")

CAM = CameraModel()
EDGE = (0.0, -0.0, 1e-300, -1e300, math.inf, -math.inf, math.nan)


def _same(a, b) -> bool:
    """Bit for bit (signed zeros included) for arrays and scalars; a NaN equals any NaN (its
    sign and payload are not specified by IEEE 754 arithmetic: BLAS and scalar code differ)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    if a.dtype.kind != "f":
        return a.tobytes() == b.tobytes()
    nan = np.isnan(a)
    if not np.array_equal(nan, np.isnan(b)):
        return False
    return a[~nan].tobytes() == b[~nan].tobytes()


def _vec(rng, n, scale=1.0, edge_p=0.03):
    v = rng.normal(size=n) * scale
    for i in range(n):
        if rng.random() < edge_p:
            v[i] = EDGE[rng.integers(len(EDGE))]
    return v


def _prm() -> np.ndarray:
    return kernels.DelayedKalmanFilter(CAM)._prm.copy()


def _cov(rng, edge_p=0.0) -> np.ndarray:
    A = rng.normal(size=(6, 6)) * 0.1
    P = A @ A.T + np.diag([1e-5, 1e-5, 1e-4, 1.0, 1.0, 1.0])
    if rng.random() < edge_p:
        P[rng.integers(6), rng.integers(6)] = EDGE[rng.integers(len(EDGE))]
    return P


def test_valid_and_step_x_equal_their_python_source():
    rng = np.random.default_rng(11)
    prm = _prm()
    for n in range(3000):
        x = _vec(rng, 6, 0.3)
        x[2] = abs(x[2]) if n % 7 else -x[2]
        assert kernels._valid(x) == kernels._valid.py_func(x)
        u = _vec(rng, 15)
        dt = float(rng.choice([0.005, 0.01, 0.3, 2.0, -0.01])) if n % 50 else math.nan
        outs = [(np.empty(6), np.empty(18), np.empty(6)) for _ in range(2)]
        kernels._step_x(x, u, dt, prm, *outs[0])
        kernels._step_x.py_func(x, u, dt, prm, *outs[1])
        for a, b in zip(*outs, strict=True):
            assert _same(a, b)


def test_propagate_equals_its_python_source():
    rng = np.random.default_rng(12)
    for _ in range(2000):
        P, F, Q = _cov(rng, 0.05), _vec(rng, 18, 0.5), np.abs(_vec(rng, 6, 1e-3))
        assert _same(kernels._propagate(P, F, Q), kernels._propagate.py_func(P, F, Q))


def test_update_equals_its_python_source():
    rng = np.random.default_rng(13)
    prm = _prm()
    accepted = 0
    for n in range(3000):
        x = np.array([0.05, -0.1, 0.05, 0.5, -0.2, 0.1]) + _vec(rng, 6, 0.02, 0.01)
        P = _cov(rng, 0.02)
        z0, z1 = x[0] + rng.normal() * 0.01, x[1] + rng.normal() * 0.01
        r_px = math.nan if n % 3 == 0 else float(abs(rng.normal(3.0, 2.0)))
        if n % 100 == 1:
            z0 = math.nan
        outs = [(np.full(6, 7.0), np.full((6, 6), 7.0)) for _ in range(2)]
        ok = kernels._update(x, P, z0, z1, r_px, prm, *outs[0])
        assert ok == kernels._update.py_func(x, P, z0, z1, r_px, prm, *outs[1])
        accepted += ok
        for a, b in zip(*outs, strict=True):
            assert _same(a, b)
    assert 1000 < accepted < 3000  # both branches taken


def _flown_filter(seed: int) -> kernels.DelayedKalmanFilter:
    """A filter 1.5 s into a tracked, manoeuvring stream (lazy covariances in its buffer)."""
    rng = np.random.default_rng(seed)
    dkf = kernels.DelayedKalmanFilter(CAM)
    R = CAM.R_BC
    u, v = 330.0, 250.0
    pending = []
    for k in range(150):
        t = 0.01 * k
        dkf.predict(t, rng.normal(size=3) * 0.3, rng.normal(size=3), R)
        u, v = u + rng.normal(), v + rng.normal()
        if k % 3 == 0:
            pending.append((t + 0.08, Detection(t, (u, v), (u - 3, v - 3, 6, 6), 28.0)))
        for p in [p for p in pending if p[0] <= t]:
            pending.remove(p)
            dkf.fuse(p[1])
    assert dkf.estimate() is not None
    return dkf


def _buffer(dkf: kernels.DelayedKalmanFilter) -> list[np.ndarray]:
    return [dkf._T, dkf._U, dkf._X, dkf._F, dkf._Q, dkf._P, dkf._HX, dkf._HP]


def _twins(seed):
    a = _flown_filter(seed)
    return a, copy.deepcopy(a)


@pytest.mark.parametrize("seed", range(4))
def test_buffer_kernels_equal_their_python_source(seed):
    """_covariance, _fuse_latest, _replay and _predict on a flown filter's buffer: the same
    return value and every buffer array the same bits."""
    rng = np.random.default_rng(100 + seed)
    a, b = _twins(seed)
    lo, hi = a._lo, a._hi
    T, _, X, F, Q, P, HX, HP = _buffer(a)
    i = int(rng.integers(lo, hi))
    assert kernels._covariance(P, F, Q, HX, HP, lo, i) == kernels._covariance.py_func(
        b._P, b._F, b._Q, b._HX, b._HP, lo, i
    )
    assert all(_same(p, q) for p, q in zip(_buffer(a), _buffer(b), strict=True))

    for _ in range(3):  # later detections, each fused at its capture time
        j = int(rng.integers(hi - 12, hi - 2))
        t_c = float(T[j] + 0.004)
        z0, z1 = float(X[j + 1, 0] + 1e-3), float(X[j + 1, 1] - 1e-3)
        r_px = float(rng.choice([math.nan, 3.1]))
        args = (j, t_c, z0, z1, r_px, a._prm)
        assert kernels._fuse_latest(*_buffer(a), a._win, *args) == kernels._fuse_latest.py_func(
            *_buffer(b), b._win, *args
        )
        assert all(_same(p, q) for p, q in zip(_buffer(a), _buffer(b), strict=True))

    j = hi - 20
    mt = np.sort(T[j] + rng.uniform(0.0, T[hi - 1] - T[j], 5))
    mz = X[j : j + 5, :2] + rng.normal(size=(5, 2)) * 1e-3
    mr = np.array([3.0, math.nan, 2.5, 3.2, math.nan])
    last = [np.array([0.3]), np.array([0.3])]
    assert a._covariance(j) is not None and b._covariance(j) is not None
    x0, P0 = X[j].copy(), P[j].copy()
    rets = [
        k(*_buffer(f), hi, j, x0.copy(), P0.copy(), float(T[j]), mt, mz, mr, 0, mt[2], a._prm, ls)
        for k, f, ls in ((kernels._replay, a, last[0]), (kernels._replay.py_func, b, last[1]))
    ]
    assert rets[0] == rets[1]
    assert _same(last[0], last[1])
    assert all(_same(p, q) for p, q in zip(_buffer(a), _buffer(b), strict=True))

    for n in range(8):  # predictions: given, missing and non-finite inputs
        gyro = _vec(rng, 3, 0.3, 0.1)
        v_c = kernels._NO_INPUT if n == 1 else _vec(rng, 3, 2.0, 0.1)
        R = np.where(rng.random((3, 3)) < 0.05, math.nan, CAM.R_BC)
        R = kernels._NO_MATRIX if n == 2 else R
        t = float(T[a._hi - 1] + 0.01)
        horizon = t - (0.6 if n < 6 else 0.05)  # the last two: most rows leave
        args = (True, t, horizon, gyro, v_c, R, a._R_CB, a._prm)
        assert kernels._predict(*_buffer(a)[:6], a._HX, a._HP, a._win, *args) == (
            kernels._predict.py_func(*_buffer(b)[:6], b._HX, b._HP, b._win, *args)
        )
        assert all(_same(p, q) for p, q in zip(_buffer(a), _buffer(b), strict=True))
        assert _same(a._win, b._win)
    assert a._lo > lo


def test_bisect_right_is_pythons():
    import bisect

    rng = np.random.default_rng(14)
    for _ in range(500):
        a = np.sort(rng.choice([0.0, 0.5, 1.0, 1.5, 2.0], size=int(rng.integers(0, 12))))
        t = float(rng.choice([-1.0, 0.0, 0.5, 0.7, 2.0, 3.0]))
        lo = int(rng.integers(0, len(a) + 1))
        hi = int(rng.integers(lo, len(a) + 1))
        want = bisect.bisect_right(a.tolist(), t, lo, hi)
        assert kernels._bisect_right(a, lo, hi, t) == kernels._bisect_right.py_func(a, lo, hi, t)
        assert kernels._bisect_right(a, lo, hi, t) == want
