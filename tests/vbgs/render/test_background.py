"""The background colour estimated from pixels without depth, as frames arrive."""

import numpy as np
import pytest

from vbgs.render import background as bg


def frame(seed, empty_fraction, sky=(0.4, 0.6, 0.9)):
    rng = np.random.default_rng(seed)
    rgb = rng.uniform(0, 1, (20, 30, 3))
    depth = rng.uniform(1, 5, (20, 30))
    no_depth = rng.uniform(size=(20, 30)) < empty_fraction
    rgb[no_depth] = sky
    depth[no_depth] = rng.choice([0.0, np.nan, np.inf], no_depth.sum())
    return rgb, depth


def test_sky_colour_is_recovered_and_order_free():
    frames = [frame(s, 0.3) for s in range(4)]
    forward, backward = bg.empty(), bg.empty()
    for rgb, depth in frames:
        forward = bg.observe(forward, rgb, depth)
    for rgb, depth in frames[::-1]:
        backward = bg.observe(backward, rgb, depth)
    np.testing.assert_allclose(bg.colour(forward), [0.4, 0.6, 0.9], atol=1e-6)
    np.testing.assert_allclose(bg.colour(forward), bg.colour(backward), atol=1e-7)


def test_beyond_max_depth_counts_as_background():
    rgb, depth = frame(0, 0.0)
    rgb[:5] = (1.0, 1.0, 1.0)
    depth[:5] = 100.0  # sensor returns beyond its range
    est = bg.observe(bg.empty(), rgb, depth, max_depth=50.0)
    np.testing.assert_allclose(bg.colour(est), [1.0, 1.0, 1.0], atol=1e-6)


def test_fully_measured_frames_fall_back_to_the_mean_colour():
    rgb, depth = frame(1, 0.0)
    est = bg.observe(bg.empty(), rgb, depth)
    assert est.empty_count == 0
    np.testing.assert_allclose(bg.colour(est), rgb.reshape(-1, 3).mean(0), atol=1e-6)
    np.testing.assert_array_equal(bg.colour(bg.empty()), np.zeros(3))


def test_parse_background():
    assert bg.parse_background("auto") is None
    np.testing.assert_allclose(bg.parse_background("1,0.5,0"), [1.0, 0.5, 0.0])
    for bad in ("1,1", "red", "2,0,0"):
        with pytest.raises(ValueError, match="R,G,B"):
            bg.parse_background(bad)


def test_holes_inside_surfaces_are_not_background():
    """Sky on the top rows (white), a grey surface with a sensor's holes (random and
    along the sky line): with holes=True only the sky counts, the estimate stays
    white; read as exact depth the holes' grey pulls it down."""
    rng = np.random.default_rng(0)
    rgb = np.full((40, 40, 3), 0.3)
    depth = np.full((40, 40), 2.0)
    rgb[:10], depth[:10] = 1.0, 0.0  # sky
    depth[10:12] = 0.0  # edge holes along the sky line: they show the surface's grey
    depth[rng.random((40, 40)) < 0.05] = 0.0
    depth[:10] = 0.0
    naive = bg.colour(bg.observe(bg.empty(), rgb, depth))
    aware = bg.colour(bg.observe(bg.empty(), rgb, depth, holes=True))
    np.testing.assert_allclose(aware, 1.0, atol=3e-3)  # a few holes touch the sky line
    assert naive.max() < 0.9
    mask = bg.empty_pixels(depth, holes=True)
    assert mask[:8].all() and mask[10:].mean() < 0.01  # the surface's holes stay out


def test_the_edge_band_shows_the_background_where_it_has_its_colour():
    """Beside a silhouette the band of depth-less pixels that empty_pixels leaves out
    (EDGE_HOLES_PX) is empty again where it has the background's colour (the opacity
    evidence reads those as passes), and stays out where it shows the surface."""
    rgb = np.full((40, 40, 3), 1.0)
    depth = np.zeros((40, 40))
    rgb[10:30, 10:30], depth[10:30, 10:30] = 0.3, 2.0  # a grey square on white
    depth[10:30, 10] = 0.0  # a sensor's edge holes on the square's own left column
    plain = bg.empty_pixels(depth, holes=True)
    aware = bg.empty_pixels(depth, holes=True, rgb=rgb, background=np.ones(3))
    band = (depth == 0) & ~plain
    assert band[9, 12] and band[12, 9]  # the band lines the square's edges
    assert aware[band & (rgb[..., 0] == 1.0)].all()  # white band pixels: background
    assert not aware[10:30, 10].any()  # the grey edge holes: still no evidence
    assert (aware == plain | (band & (rgb[..., 0] == 1.0))).all()


def _by_propagation(depth, rgb, background, tol=bg.BACKGROUND_TOL):
    """empty_pixels as SciPy's erosion and propagation give it: the reference."""
    from scipy import ndimage

    no_depth = ~(np.isfinite(depth) & (depth > 0))
    inner = ndimage.binary_erosion(no_depth, iterations=bg.EDGE_HOLES_PX, border_value=1)
    seeds = np.zeros_like(inner)
    seeds[[0, -1], :], seeds[:, [0, -1]] = inner[[0, -1], :], inner[:, [0, -1]]
    empty = ndimage.binary_propagation(seeds, mask=inner)
    like = np.all(np.abs(rgb - background) <= tol, axis=-1)
    return empty, empty | (ndimage.binary_propagation(empty, mask=no_depth) & like)


@pytest.mark.parametrize("seed", range(4))
def test_empty_pixels_are_the_border_regions_scipy_propagates(seed):
    """Random blobs without depth (some reaching the border, some inside, some joined by
    thin necks the erosion cuts) and two colours: the labelled regions are exactly the
    pixels SciPy's erosion and binary propagation give, with and without the band's
    background colour."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    blobs = ndimage.gaussian_filter(rng.random((48, 64)), 2.0)
    depth = np.where(blobs > np.quantile(blobs, 0.55), 0.0, 2.0)
    depth[rng.random(depth.shape) < 0.05] = np.nan  # dropouts
    rgb = np.where(rng.random((48, 64, 1)) < 0.5, [0.9, 0.9, 0.9], [0.2, 0.3, 0.4])
    plain, aware = _by_propagation(depth, rgb, np.full(3, 0.95))
    got = bg.empty_pixels(depth, holes=True)
    np.testing.assert_array_equal(got, plain)
    np.testing.assert_array_equal(
        bg.empty_pixels(depth, holes=True, rgb=rgb, background=np.full(3, 0.95)), aware)
    assert 0 < plain.sum() < aware.sum() < (~(depth > 0)).sum()  # each rule leaves some out
