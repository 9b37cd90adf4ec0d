"""The mono model: depth on every pixel, a few per cent of error per frame that is
smooth over the image (not white), drifting from frame to frame, edges bled."""

import numpy as np
import pytest

from vbgs.data.synthetic import object_scene
from vbgs.render.camera import Camera
from vbgs.sensors import Mono, simulate
from vbgs.sensors.holes import depth_edges
from vbgs.sensors.mono import FAR_FACTOR, dilate


@pytest.fixture(scope="module")
def frames():
    return object_scene(size=64, n_train=6, n_test=1, n_val=0).train


def lag1(error: np.ndarray, mask: np.ndarray) -> float:
    """Correlation of an error map with itself one pixel to the right, over ``mask``."""
    both = mask[:, :-1] & mask[:, 1:]
    return float(np.corrcoef(error[:, :-1][both], error[:, 1:][both])[0, 1])


def relative_error(out, depth):
    ok = depth > 0
    return np.where(ok, out.astype(np.float64) / np.where(ok, depth, 1.0) - 1.0, 0.0)


def test_depth_on_every_pixel_background_included(frames):
    for i, f in enumerate(frames):
        out = simulate("mono", f.depth, f.camera, seed=[0, i])
        assert out.dtype == np.float32 and np.isfinite(out).all() and (out > 0).all()
        background = f.depth == 0
        assert 0.5 < background.mean() < 0.8  # the white background of the object scene
        # away from the silhouette (where the object bleeds in), about 1.5 x the farthest
        far = background & ~dilate(~background, 3)
        ratio = out[far] / (FAR_FACTOR * f.depth.max())
        assert 0.85 < ratio.min() and ratio.max() < 1.15


def test_a_few_per_cent_of_smooth_error_per_frame(frames):
    """Measured, seed [0, i]: mean |relative error| 1.3-5.2 % per frame away from edges;
    the correlation of neighbouring pixels' errors >= 0.994 (the kinect's: within
    +-0.12, white)."""
    medians = []
    for i, f in enumerate(frames):
        ok = f.depth > 0
        away = ok & ~dilate(depth_edges(f.depth, camera=f.camera), 3)
        mono = relative_error(simulate("mono", f.depth, f.camera, seed=[0, i]), f.depth)
        assert 0.005 < np.abs(mono[away]).mean() < 0.08
        assert lag1(mono, away) > 0.98
        kinect = simulate("kinect", f.depth, f.camera, seed=[0, i])
        assert abs(lag1(relative_error(kinect, f.depth), away & (kinect > 0))) < 0.2
        medians.append(np.median(mono[away]))
    assert np.std(medians) > 0.01  # the scale and shift drift from frame to frame


def test_edges_bleed_over_two_pixels():
    """Drift and warp off: a step from 1 to 2 m is smeared over two pixels each side."""
    cam = Camera(100.0, 100.0, 32.0, 32.0, 64, 64, np.eye(4))
    depth = np.full((64, 64), 1.0, np.float32)
    depth[:, 32:] = 2.0
    bleed = Mono(scale_drift=0.0, shift_drift=0.0, warp=0.0)
    out = bleed.simulate(depth, cam, np.random.default_rng(0))
    row = out[10]  # edge pixels: columns 31 and 32; the band: 2 px beyond them
    assert (row[:29] == 1.0).all() and (row[35:] == 2.0).all()
    assert row[29] < 1.01 and row[34] > 1.99  # the blur's tail (sigma 1 px)
    assert 1.05 < row[30] < row[31] < row[32] < row[33] < 1.95
    assert np.all(np.diff(row) >= 0)  # a smooth ramp across the edge
    level0 = bleed.simulate(depth, cam, np.random.default_rng(0), level=0.0)
    np.testing.assert_array_equal(level0, depth)


def test_warp_is_bounded_by_its_amplitude():
    cam = Camera(100.0, 100.0, 32.0, 32.0, 64, 64, np.eye(4))
    depth = np.full((64, 64), 3.0, np.float32)
    warp_only = Mono(scale_drift=0.0, shift_drift=0.0)
    for seed in range(5):
        ratio = warp_only.simulate(depth, cam, np.random.default_rng(seed)) / 3.0
        assert np.abs(ratio - 1).max() <= 0.05 + 1e-6 and np.abs(ratio - 1).max() > 0.005
        ratio2 = warp_only.simulate(depth, cam, np.random.default_rng(seed), level=2.0) / 3.0
        np.testing.assert_allclose(ratio2 - 1, 2 * (ratio - 1), atol=1e-6)


def test_sigma_z_is_relative():
    mono = Mono()
    assert mono.sigma_z(2.0) == pytest.approx(2 * mono.sigma_z(1.0))
    assert 0.03 < mono.relative_sigma() < 0.06  # sqrt(3^2 + 2^2 + 2.5^2) = 4.4 %
    # what is left after the per-frame alignment (depth.perframe): 70 % of it
    assert mono.sigma_z(1.0) == pytest.approx(0.7 * mono.relative_sigma())
    assert mono.sigma_z(1.0, level=2.0) == pytest.approx(2 * mono.sigma_z(1.0))


def test_a_frame_without_depth_is_refused():
    cam = Camera(100.0, 100.0, 8.0, 8.0, 16, 16, np.eye(4))
    with pytest.raises(ValueError, match="has none"):
        simulate("mono", np.zeros((16, 16), np.float32), cam, seed=0)
