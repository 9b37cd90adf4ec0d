"""A frame's depth averaged over its surface (vbgs.mapping.denoise): the noise left is
the one the fit predicts, edges stay edges, holes stay holes."""

import jax
import numpy as np
import pytest

from vbgs import mapping
from vbgs.data.synthetic import make_scene
from vbgs.mapping.denoise import noise_left, sensor_radius, smoothed
from vbgs.sensors import simulate

FOCAL = 100.0
SIGMA = 0.02


def plane_depth(h=60, w=80):
    """The z-depth of a tilted plane (1/z affine in the pixel coordinates)."""
    v, u = np.mgrid[0:h, 0:w]
    return 1.0 / (0.3 + 0.0005 * (u - w / 2) + 0.0003 * (v - h / 2))


def noisy(z, seed=0):
    rng = np.random.default_rng(seed)
    return (z + SIGMA * rng.standard_normal(z.shape)).astype(np.float32)


def test_a_noisy_plane_keeps_the_noise_the_fit_predicts():
    z = plane_depth()
    out, factor = smoothed(noisy(z), np.full(z.shape, SIGMA), FOCAL, radius=2)
    inner = np.s_[2:-2, 2:-2]  # full 5 x 5 windows: 25 readings, leverage 1/25 (a reading
    #                            beyond 3 sigma of the plane, left out, makes it 1/24)
    assert np.median(factor[inner]) == pytest.approx(0.2, abs=1e-4)
    assert factor[inner].max() < 0.21
    rms = np.sqrt(np.mean((out - z)[inner] ** 2))
    assert 0.18 * SIGMA < rms < 0.22 * SIGMA  # measured 0.21 sigma
    border = factor[0, 0]  # a corner's window holds 9 readings, the plane extrapolated
    assert 0.2 < border < 1.0


def test_holes_stay_holes_and_are_no_surface():
    z = noisy(plane_depth())
    z[20:30, 30:40] = 0.0
    z[5, 5] = np.nan
    out, factor = smoothed(z, np.full(z.shape, SIGMA), FOCAL)
    assert (out[20:30, 30:40] == 0).all() and np.isnan(out[5, 5])
    assert (factor[20:30, 30:40] == 1).all()
    # beside the hole the fit reads only the surface: the error stays small
    ring = out[18:20, 30:40] - plane_depth()[18:20, 30:40]
    assert np.abs(ring).max() < 2.5 * SIGMA


def test_a_depth_edge_is_not_smoothed_across():
    """Two planes 1 m apart side by side: each pixel's fit reads its own plane only, so
    no depth lands between them."""
    z = plane_depth()
    z[:, 40:] += 1.0
    out, _ = smoothed(noisy(z), np.full(z.shape, SIGMA), FOCAL)
    err = np.abs(out - z)
    assert err.max() < 4 * SIGMA  # measured ~2 sigma at the edge columns, 0.2 sigma inside
    assert np.abs(out[:, 39] - z[:, 39]).mean() < SIGMA


def test_radius_zero_changes_nothing():
    z = noisy(plane_depth())
    out, factor = smoothed(z, np.full(z.shape, SIGMA), FOCAL, radius=0)
    assert out is z and (factor == 1).all()


def test_only_pixel_to_pixel_noise_is_smoothed():
    """A depth network's error is smooth: nothing to average; exact depth has none."""
    assert mapping.SensorConfig("kinect").white
    assert mapping.SensorConfig("realsense").white
    assert not mapping.SensorConfig("mono").white
    assert not mapping.SensorConfig("exact").white
    assert not mapping.SensorConfig("kinect", level=0.0).white
    with pytest.raises(ValueError, match="growth.denoise_radius must be an integer"):
        mapping.GrowthConfig(denoise_radius=-1)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_float32_holds_at_any_scale_of_the_scene(scale):
    """The fit runs in float32 (inverse depths and window sums): a scene in millimetres
    or kilometres keeps the same share of its noise."""
    z = plane_depth() * scale
    sigma = np.full(z.shape, SIGMA * scale)
    rng = np.random.default_rng(1)
    measured = (z + sigma * rng.standard_normal(z.shape)).astype(np.float32)
    out, factor = smoothed(measured, sigma, FOCAL, radius=2)
    assert out.dtype == np.float32
    rms = np.sqrt(np.mean((out - z)[2:-2, 2:-2] ** 2)) / scale
    assert 0.18 * SIGMA < rms < 0.22 * SIGMA


def test_a_frame_takes_the_median_share_of_its_noise():
    z = noisy(plane_depth())
    z[:, :10] = 0.0
    out, factor = smoothed(z, np.full(z.shape, SIGMA), FOCAL, radius=1)  # 3 x 3
    assert noise_left(out, factor) == pytest.approx(1 / 3, abs=1e-4)
    assert noise_left(np.zeros_like(z), factor) == 1.0


def test_each_sensor_averages_over_its_own_window_unless_one_is_chosen():
    """The RealSense's noise spans several footprints: its readings are averaged over a
    7 x 7 window, the Kinect's over 3 x 3 (each chosen on its own validation views);
    ``growth.denoise_radius`` overrides both."""
    assert mapping.GrowthConfig().denoise_radius is None
    assert sensor_radius("kinect") == 1 and sensor_radius("realsense") == 3
    assert sensor_radius("realsense", 0) == 0 and sensor_radius("kinect", 2) == 2
    sensed = {name: mapping.Config(sensor=mapping.SensorConfig(name))
              for name in ("kinect", "realsense")}
    assert {n: c.denoise_radius for n, c in sensed.items()} == {"kinect": 1, "realsense": 3}
    chosen = mapping.Config(sensor=mapping.SensorConfig("realsense"),
                            growth=mapping.GrowthConfig(denoise_radius=2))
    assert chosen.denoise_radius == 2
    with pytest.raises(ValueError, match=r"or None \(the sensor's own\)"):
        mapping.GrowthConfig(denoise_radius=True)


def test_the_realsense_frame_is_averaged_over_its_wider_window():
    """A map learned under the RealSense model is, to the bit, the one learned with radius
    3 chosen, and not the one with radius 1."""
    scene = make_scene("object", size=32, n_train=1, n_test=1, seed=0)
    frame = scene.train[0]
    frame = frame._replace(depth=simulate("realsense", frame.depth, frame.camera,
                                          rng=np.random.default_rng(0)))
    means = {}
    for chosen in (None, 3, 1):
        config = mapping.Config(components=500, sensor=mapping.SensorConfig("realsense"),
                                growth=mapping.GrowthConfig(denoise_radius=chosen))
        state = mapping.init(config, key=jax.random.key(0))
        state, _ = mapping.update(state, frame, config)
        means[chosen] = np.asarray(state.mixture.posterior.space.mean)
    assert np.array_equal(means[None], means[3])
    assert not np.array_equal(means[None], means[1])
