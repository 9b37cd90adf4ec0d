"""The registry and ``simulate``: level 0 keeps depth exact, a seed gives the same
depth, frames get noise of their own, bad input is refused naming the choices."""

import numpy as np
import pytest

from vbgs.data.synthetic import object_scene
from vbgs.sensors import SENSOR_NAMES, SENSORS, simulate

NOISY = ("kinect", "realsense", "mono")


@pytest.fixture(scope="module")
def frames():
    return object_scene(size=48, n_train=3, n_test=1, n_val=0).train


def test_the_registry():
    assert SENSOR_NAMES == ("exact", "kinect", "realsense", "mono")
    assert all(SENSORS[name].name == name for name in SENSOR_NAMES)


def test_exact_is_the_identity(frames):
    f = frames[0]
    out = simulate("exact", f.depth, f.camera, seed=0)
    np.testing.assert_array_equal(out, f.depth)
    assert out is not f.depth


@pytest.mark.parametrize("name", NOISY)
def test_level_zero_keeps_every_depth_exact(name, frames):
    for i, f in enumerate(frames):
        out = simulate(name, f.depth, f.camera, seed=[0, i], level=0.0)
        kept = (out > 0) & (f.depth > 0)
        np.testing.assert_array_equal(out[kept], f.depth[kept])
        assert kept.sum() > 0.6 * (f.depth > 0).sum()  # only the physical holes


@pytest.mark.parametrize("name", NOISY)
def test_seeded_and_different_per_frame(name, frames):
    f = frames[0]
    a = simulate(name, f.depth, f.camera, seed=[3, 0])
    np.testing.assert_array_equal(a, simulate(name, f.depth, f.camera, seed=[3, 0]))
    np.testing.assert_array_equal(
        a, simulate(name, f.depth, f.camera, rng=np.random.default_rng([3, 0])))
    b = simulate(name, f.depth, f.camera, seed=[3, 1])  # the next frame's stream
    both = (a > 0) & (b > 0) & (f.depth > 0)
    # kinect: 46 % of the pixels differ (depth 3-4.5 m comes in 3-6 cm steps)
    assert np.mean(a[both] != b[both]) > 0.3
    assert not np.array_equal(a == 0, b == 0) or name == "mono"  # random holes move
    assert not np.array_equal(a, f.depth)


@pytest.mark.parametrize("name", NOISY)
def test_level_scales_the_error(name, frames):
    f = frames[1]
    ok = f.depth > 0

    def error(level):
        out = simulate(name, f.depth, f.camera, seed=5, level=level).astype(np.float64)
        kept = ok & (out > 0)
        return np.median(np.abs(out[kept] - f.depth[kept]))

    assert error(0.5) < error(1.0) < error(2.0)


def test_bad_input_is_refused(frames):
    f = frames[0]
    with pytest.raises(ValueError, match="use one of exact, kinect, realsense, mono"):
        simulate("lidar", f.depth, f.camera, seed=0)
    for level in (-0.5, float("nan"), float("inf"), True, "1"):
        with pytest.raises(ValueError, match="sensor level must be"):
            simulate("kinect", f.depth, f.camera, seed=0, level=level)
    with pytest.raises(ValueError, match="exactly one of rng"):
        simulate("kinect", f.depth, f.camera)
    with pytest.raises(ValueError, match="exactly one of rng"):
        simulate("kinect", f.depth, f.camera, seed=0, rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match="to match the camera"):
        simulate("mono", f.depth[:, :-1], f.camera, seed=0)
