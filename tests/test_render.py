"""The renderer's shortcuts draw the same frames: the noise frames drawn from the
stream's bytes equal ``rng.integers``'s, and the one-pass noise equals the saturating add
then subtract."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation.sim.render import FrameRenderer, uniform_uint8
from onboard.camera_model import CameraModel

CAM = CameraModel(640, 480, 90.0, 0.0, 0.0)


@pytest.mark.parametrize("high", [0, 1, 2, 3, 7, 100, 127, 255])
@pytest.mark.parametrize("shape", [(480, 640, 3), (5, 7, 3)])
def test_uniform_uint8_is_rng_integers_and_leaves_the_stream_where_it_does(high, shape):
    a, b = np.random.default_rng(42), np.random.default_rng(42)
    for _ in range(3):
        want = a.integers(0, high + 1, shape, dtype=np.uint8)
        got = uniform_uint8(b, high, shape)
        assert got.dtype == np.uint8 and got.shape == shape
        assert np.array_equal(got, want)
    assert a.integers(0, 1 << 40) == b.integers(0, 1 << 40)


def _reference_render(r: FrameRenderer, *args, **kw) -> np.ndarray:
    """The frame as drawn before the one-pass noise: saturating add, then subtract."""
    one_pass = r._one_pass
    r._one_pass = False
    try:
        return r.render(*args, **kw)
    finally:
        r._one_pass = one_pass


def test_one_pass_noise_gives_the_same_frames():
    a = FrameRenderer(CAM, np.random.default_rng(5))
    b = FrameRenderer(CAM, np.random.default_rng(5))
    assert a._one_pass  # the default colours and noise never saturate
    rng = np.random.default_rng(9)
    for i in range(60):
        R = Rotation.random(random_state=i).as_matrix()
        target = rng.normal(0.0, 5.0, 3) + np.array([0.0, 0.0, 8.0])
        kw = dict(clutter_px=(300.0, 200.0, 9.0)) if i % 4 == 0 else {}
        got = a.render(R, np.zeros(3), R @ target, 0.6, **kw)
        want = _reference_render(b, R, np.zeros(3), R @ target, 0.6, **kw)
        assert np.array_equal(got, want), i
    # brightness changes take the saturating path, as before
    frame = a.render(np.eye(3), np.zeros(3), np.array([0.0, 0.0, 5.0]), 0.6, brightness=1.6)
    assert frame.max() == 255
    # a noise level that could saturate turns the one pass off
    assert not FrameRenderer(CAM, np.random.default_rng(1), noise_level=30)._one_pass
