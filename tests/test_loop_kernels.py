"""The loop tick's fused kernels (its LOS terms, its command, the DKF's reads, the attitudes
and the simulated camera's projection) give their Python source's results bit for bit on
seeded random inputs, do what the Python they replaced did (the early/late tick's carry, the
low-pass, the output guard, the buffered estimate's look-up), and sum their products in index
order, so a sortie's numbers do not depend on the CPU's BLAS kernel."""

from __future__ import annotations

import dataclasses
import math
import struct

import numpy as np
import pytest

from groundstation.scenario import EstimateSpec
from groundstation.sim.camera import sphere_image
from groundstation.sim.estimate import StateEstimateModel
from onboard.camera_model import CameraModel
from onboard.control.attitude import attitude_floats, command_floats
from onboard.control.disturbance import feedforward_floats
from onboard.control.guidance import (
    angles_floats,
    los_floats,
    los_terms,
    normal_floats,
    smooth_los_change,
)
from onboard.datatypes import Detection
from onboard.estimation.dkf import DelayedKalmanFilter, _view
from onboard.geometry import (
    body_and_camera_attitude,
    mat3_mul,
    quat_to_rotmat,
    rotmat_of_quat,
    wrap_pi,
)

# the comparisons of a compiled kernel with its Python source (the rest runs either way)
compiled = pytest.mark.skipif(
    not hasattr(los_terms, "py_func"), reason="PEREGRINE_JIT=0: no compiled kernels"
)

N = 2000


def _bits(out) -> tuple:
    vals = out if isinstance(out, tuple) else (out,)
    return tuple(b"nan" if math.isnan(v) else struct.pack("<d", float(v)) for v in vals)


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.standard_normal(4)
    return quat_to_rotmat(q / np.linalg.norm(q))


@compiled
def test_index_order_products_are_the_python_floats_and_close_to_numpy():
    rng = np.random.default_rng(2101)
    for _ in range(N):
        A, B = _rotation(rng), rng.standard_normal((3, 3))
        C = mat3_mul(A, B)
        for i in range(3):
            for j in range(3):  # sums in index order, no FMA: what Python's floats give
                ref = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]
                assert _bits(float(C[i, j])) == _bits(float(ref))
        np.testing.assert_allclose(C, A @ B, rtol=0, atol=1e-14)
        ex, ey = rng.standard_normal(2).tolist()
        n = los_floats(ex, ey, A)
        assert _bits(n) == _bits(los_floats.py_func(ex, ey, A))
        r = A @ np.array([ex, ey, 1.0])
        np.testing.assert_allclose(n, r / np.linalg.norm(r), rtol=0, atol=1e-15)
        q = rng.standard_normal(4)
        q /= np.linalg.norm(q)
        R_WB, R_WC = body_and_camera_attitude(q, B)
        assert _bits(tuple(R_WB.ravel())) == _bits(tuple(rotmat_of_quat.py_func(q).ravel()))
        assert _bits(tuple(R_WC.ravel())) == _bits(tuple(mat3_mul(R_WB, B).ravel()))


def test_a_quaternion_of_the_wrong_length_is_refused():
    with pytest.raises(ValueError, match="4 components"):
        quat_to_rotmat([1.0, 0.0, 0.0])
    np.testing.assert_array_equal(quat_to_rotmat([1, 0, 0, 0]), np.eye(3))


def test_wrap_pi_is_the_fmod_formula_to_the_bit():
    def ref(a: float) -> float:
        r = math.fmod(a + math.pi, 2.0 * math.pi)
        return (r + 2.0 * math.pi if r <= 0.0 else r) - math.pi

    rng = np.random.default_rng(2102)
    xs = (rng.standard_normal(50_000) * rng.choice([1e-9, 1.0, 10.0, 1e4], 50_000)).tolist()
    xs += [0.0, -0.0, math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 2 * math.pi, 1e-300]
    for x in xs:
        assert _bits(wrap_pi(x)) == _bits(ref(x)), x
    assert math.isnan(wrap_pi(math.inf)) and math.isnan(wrap_pi(math.nan))


def _los_args(rng: np.random.Generator) -> tuple:
    ex, ey, pex, pey = (rng.standard_normal(4) * 200.0).tolist()
    dt = float(rng.choice([0.01, 0.005, 0.0025, 0.02, 0.05]))
    hold = float(rng.choice([dt, 0.005, 0.01]))
    flown = (
        (math.nan,) * 3
        if rng.random() < 0.2
        else (*(rng.standard_normal(2) * 0.01).tolist(), float(rng.choice([0.005, 0.01])))
    )
    noise = (rng.standard_normal(2) * 0.01).tolist()
    filt = (math.nan,) * 2 if rng.random() < 0.2 else tuple(noise)
    return (
        ex, ey, 320.0, _rotation(rng), bool(rng.random() < 0.9), pex, pey, _rotation(rng),
        dt, hold, bool(rng.random() < 0.7), float(rng.choice([0.0, 0.0, 0.1])),
        *filt, *flown, 1.0,
    )  # fmt: skip


@compiled
def test_los_terms_match_their_source():
    rng = np.random.default_rng(2103)
    for _ in range(N):
        args = _los_args(rng)
        assert _bits(los_terms(*args)) == _bits(los_terms.py_func(*args)), args


def test_los_terms_carry_the_unflown_part_of_the_last_command():
    rng = np.random.default_rng(2104)
    R, R_prev = _rotation(rng), _rotation(rng)
    f = 320.0

    def terms(dt, hold, flown, given=True, tau=0.0, filt=(math.nan, math.nan)):
        return los_terms(
            30.0, -20.0, f, R, True, 25.0, -18.0, R_prev, dt, hold, given, tau, *filt, *flown, 1.0
        )

    q = angles_floats(*los_floats(30.0 / f, -20.0 / f, R))
    qp = angles_floats(*los_floats(25.0 / f, -18.0 / f, R_prev))
    raw = (q[0] - qp[0], wrap_pi(q[1] - qp[1]))
    none = (math.nan,) * 3
    out = terms(0.005, 0.005, none)
    assert out[3:7] == (*q, *raw) and out[9:] == (*raw, 0.005)  # nothing carried; remembered
    flown = (0.01, -0.02, 0.005)
    early = terms(0.0025, 0.005, flown)  # half the last hold: half its change not flown
    assert early[5:7] == (raw[0] + 0.01 * 0.5, raw[1] + -0.02 * 0.5)
    late = terms(0.0075, 0.005, flown)  # held half a hold too long: half of it taken back
    assert late[5:7] == (raw[0] + 0.01 * -0.5, raw[1] + -0.02 * -0.5)
    stall = terms(0.05, 0.005, flown)  # at most one whole hold's worth
    assert stall[5:7] == (raw[0] - 0.01, raw[1] + 0.02)
    assert terms(0.005, 0.005, flown)[5:7] == raw  # on time: nothing to carry
    fixed = terms(0.0025, 0.0025, flown, given=False)  # a fixed grid: no hold, no carry
    assert fixed[5:7] == raw and fixed[9:] == flown
    # the low-pass instead: over dt, per hold, from the filter's state
    lp = terms(0.0025, 0.005, flown, tau=0.1, filt=(0.002, -0.001))
    k = 0.005 / 0.0025
    want = (
        smooth_los_change(0.002, raw[0] * k, 0.0025, 0.1),
        smooth_los_change(-0.001, raw[1] * k, 0.0025, 0.1),
    )
    assert lp[5:7] == want and lp[7:9] == want and lp[9:] == flown
    first = terms(0.005, 0.005, none, given=False)
    assert first[5:7] == raw  # no previous estimate below: no change at all
    no_prev = los_terms(
        30.0, -20.0, f, R, False, 0.0, 0.0, R, 0.005, 0.005, True, 0.0, *(math.nan,) * 5, 1.0
    )
    assert no_prev[5:7] == (0.0, 0.0)


@compiled
def test_the_command_kernel_is_feed_forward_attitude_and_guard():
    rng = np.random.default_rng(2105)
    for i in range(N):
        a = (rng.standard_normal(3) * 5.0).tolist()
        if i % 40 == 0:
            a[rng.integers(3)] = math.nan
        d, v = (rng.standard_normal(3) * 0.5).tolist(), (rng.standard_normal(3) * 4.0).tolist()
        R, yaw, ff = _rotation(rng), float(rng.standard_normal()), bool(rng.random() < 0.7)
        args = (*a, ff, *d, *v, 0.5, R, yaw, 8.0, 4.0, 1.5, 44.1, 0.33)
        out = command_floats(*args)
        assert _bits(out) == _bits(command_floats.py_func(*args))
        c = a
        if ff:
            fd = feedforward_floats(*d, *v, 0.5)
            c = [c[0] + fd[0], c[1] + fd[1], c[2] + fd[2]]
        w0, w1, w2, thrust = attitude_floats(*c, R, yaw, 8.0, 4.0, 1.5, 44.1)
        ok = all(math.isfinite(x) for x in (w0, w1, w2, thrust)) and 0.0 <= thrust <= 1.0
        want = (w0, w1, w2, thrust, 0.0) if ok else (0.0, 0.0, 0.0, 0.33, 1.0)
        assert _bits(out[:5]) == _bits(want)
        assert _bits(out[5]) == _bits(normal_floats(*a, *v))


@compiled
def test_the_projection_kernel_matches_its_source_and_the_pinhole():
    rng = np.random.default_rng(2106)
    cam = CameraModel(640, 480, 90.0, 20.0, 0.0)
    for _ in range(N):
        R = _rotation(rng)
        c, t = rng.standard_normal(3) * 3.0, rng.standard_normal(3) * 30.0
        args = (R, *c.tolist(), *t.tolist(), 0.5, cam.f_px, cam.cu_px, cam.cv_px)
        out = sphere_image(*args)
        assert _bits(out) == _bits(sphere_image.py_func(*args))
        p = R.T @ (t - c)
        np.testing.assert_allclose(out[3], cam.f_px * 0.25 / math.sqrt(p @ p - 0.0625), rtol=1e-12)
        if p[2] > 1e-6:
            assert out[0] == 1.0
            np.testing.assert_allclose(out[1:3], cam.project(p), rtol=1e-12)
        else:
            assert out[0] == 0.0 and math.isnan(out[1]) and cam.project(p) is None


def _flown_dkf() -> DelayedKalmanFilter:
    """A DKF after two seconds of ticks at 100 Hz with detections at 30 Hz, 80 ms late."""
    cam = CameraModel(640, 480, 90.0, 0.0, 0.0)
    dkf = DelayedKalmanFilter(cam)
    rng = np.random.default_rng(2107)
    R_WC = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    for k in range(1, 201):
        t = 0.01 * k
        dkf.predict(t, rng.standard_normal(3) * 0.05, np.array([0.0, 3.0, 0.0]), R_WC)
        if k % 3 == 0 and t > 0.1:
            u, v = 320.0 + 20.0 * math.sin(t) + rng.standard_normal(), 240.0 + rng.standard_normal()
            dkf.fuse(Detection(t - 0.08, (u, v), (u - 6.0, v - 6.0, 12.0, 12.0), 113.0))
    return dkf


@compiled
def test_the_dkf_reads_one_kernel_as_the_buffer_holds_them():
    dkf = _flown_dkf()
    T, X, HX, f = dkf._T, dkf._X, dkf._HX, dkf._f
    lo, hi = dkf._win.tolist()
    args = (T, dkf._U, X, HX, dkf._win, True, dkf._last_accepted_s, 0.5, f)
    for at in [*T[lo:hi].tolist(), 0.0, T[hi - 1] + 1.0, T[hi - 1] - 0.0049]:
        out = _view(*args, True, at)
        assert _bits(out) == _bits(_view.py_func(*args, True, at))
    est, prev, rng_m = dkf.view(float(T[hi - 2]))
    i = hi - 1
    assert est.time_s == T[i] and est.e_px == (X[i, 0] * f, X[i, 1] * f)
    assert prev == (X[i - 1, 0] * f, X[i - 1, 1] * f) and HX[i - 1]
    assert rng_m == math.sqrt(1.0 + X[i, 0] ** 2 + X[i, 1] ** 2) / X[i, 2]
    assert dkf.estimate() == est and dkf.range_m() == rng_m
    assert dkf.e_px_at(float(T[hi - 2])) == prev
    assert dkf.e_px_at(float(T[hi - 2]) + 0.004) is None  # no prediction at that time
    assert dkf.view()[1] is None  # no time asked for
    # the image rate: the rotational plus the translational flow of the newest row's state
    # with its inputs (U: camera rate, vehicle velocity, R_CW row-major); state_vector's r
    # is the translational part
    xn, yn, rho, vE, vN, vU = X[i].tolist()
    wx, wy, wz, c0, c1, c2, *r = dkf._U[i].tolist()
    d = (vE - c0, vN - c1, vU - c2)
    u = [r[3 * k] * d[0] + r[3 * k + 1] * d[1] + r[3 * k + 2] * d[2] for k in range(3)]
    rot = (xn * yn * wx - (1.0 + xn * xn) * wy + yn * wz,
           (1.0 + yn * yn) * wx - xn * yn * wy - xn * wz)  # fmt: skip
    tr = (rho * (u[0] - xn * u[2]), rho * (u[1] - yn * u[2]))
    assert est.e_rate_px_s == ((rot[0] + tr[0]) * f, (rot[1] + tr[1]) * f)
    assert abs(est.e_rate_px_s[0]) > 1e-3  # a real rate, not a zero that matches anything
    state, _ = dkf.state_vector()
    assert state.tolist() == [*est.e_px, tr[0] * f, tr[1] * f]
    fresh = DelayedKalmanFilter(CameraModel())
    assert fresh.view(0.0) == (None, None, None)


def test_a_stamped_detection_keeps_every_field_but_its_time():
    det = Detection(1.25, (100.0, 200.0), (94.0, 194.0, 12.0, 12.0), 113.0, score=0.7)
    spec = dataclasses.replace(EstimateSpec(), camera_time_offset_s=0.005)
    model = StateEstimateModel(spec, np.random.SeedSequence(3))
    out = model.stamp(det)
    for field in dataclasses.fields(Detection):
        if field.name != "capture_time_s":
            assert getattr(out, field.name) == getattr(det, field.name), field.name
    assert out.capture_time_s != det.capture_time_s
