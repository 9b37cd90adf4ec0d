"""The prior's length scale from the cells the data occupy (vbgs.inference.area), known answers."""

import jax
import numpy as np
import pytest

from vbgs.inference import expfam, model
from vbgs.inference.area import occupied_cell_length, occupied_cells


def _plane(width, height, spacing, normal=(0.0, 0.0, 1.0)):
    """Grid points ``[n, 3]`` on a width x height rectangle through the origin, spacing
    ``spacing``, in the plane with the given normal."""
    u, v = np.meshgrid(np.arange(0, width, spacing), np.arange(0, height, spacing))
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    return u.reshape(-1, 1) * a + v.reshape(-1, 1) * b  # [n, 3]


def _ell(xyz, k):
    lo, hi = xyz.min(0), xyz.max(0)
    return occupied_cell_length(xyz, k, lo, model.cell_length(lo, hi, k))


def test_axis_aligned_plane_gives_sqrt_area_over_k():
    pts = _plane(2.0, 3.0, 0.01) + [0.0, 0.0, 0.5]  # area 6
    pts = np.concatenate([pts, [[0.0, 0.0, 0.0], [2.0, 3.0, 1.0]]])  # a 2 x 3 x 1 box around it
    for k in (600, 2400):  # cells of 0.1 and 0.05: the partial cells along the edges stay few
        assert _ell(pts, k) == pytest.approx(np.sqrt(6.0 / k), rel=0.06)
        # the box cell would be (6 / k)^(1/3): much larger
        assert model.cell_length(pts.min(0), pts.max(0), k) > 1.5 * np.sqrt(6.0 / k)


def test_tilted_plane_counts_the_cubes_it_crosses():
    """A plane with unit normal n crosses |n|_1 / h^2 cubes of side h per unit area, so
    ell = sqrt(|n|_1 A / K): sqrt(3) A for the (1, 1, 1) diagonal."""
    pts = _plane(2.0, 2.0, 0.006, normal=(1.0, 1.0, 1.0))  # area 4
    assert _ell(pts, 800) == pytest.approx(np.sqrt(np.sqrt(3.0) * 4.0 / 800), rel=0.06)


def test_more_components_give_finer_cells_as_a_surface_should():
    pts = _plane(2.0, 2.0, 0.01) + [0.0, 0.0, 0.3]
    pts = np.concatenate([pts, [[0.0, 0.0, 0.0], [2.0, 2.0, 1.0]]])
    ratio = _ell(pts, 1600) / _ell(pts, 400)
    assert ratio == pytest.approx(0.5, rel=0.05)  # K^(-1/2), not the box's K^(-1/3)


def test_data_filling_the_box_keep_the_box_cell():
    u = np.arange(64) + 0.5  # an image's pixel centres fill their 2-D box
    pix = np.stack(np.meshgrid(u, u), -1).reshape(-1, 2)
    lo, hi = pix.min(0), pix.max(0)
    upper = model.cell_length(lo, hi, 2000)
    assert occupied_cell_length(pix, 2000, lo, upper) == upper
    vol = np.random.default_rng(0).uniform(0, 1, (40000, 3))  # a filled cube
    assert _ell(vol, 500) == pytest.approx(model.cell_length(vol.min(0), vol.max(0), 500),
                                           rel=0.1)


def test_fewer_points_than_components_give_about_their_spacing():
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    lo = pts.min(0)
    ell = occupied_cell_length(pts, 100, lo, upper=10.0)  # 4 points: the target is 4 cells
    assert occupied_cells(pts, lo, ell) == 4  # every point in a cell of its own
    assert 0.5 < ell <= 1.0  # the largest such cell: about the points' spacing (1)


def test_occupied_cells_counts_distinct_cells():
    pts = np.array([[0.1, 0.1], [0.2, 0.3], [1.5, 0.1], [1.5, 2.9]])
    assert occupied_cells(pts, np.zeros(2), 1.0) == 3
    assert occupied_cells(pts, np.zeros(2), 10.0) == 1


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="points"):
        occupied_cell_length(np.zeros((0, 3)), 10, np.zeros(3), 1.0)
    with pytest.raises(ValueError, match="upper"):
        occupied_cell_length(np.zeros((2, 3)), 10, np.zeros(3), 0.0)


def test_init_scales_the_prior_by_the_surface_length():
    pts = (_plane(2.0, 2.0, 0.02) + [0.0, 0.0, 0.3]).astype(np.float32)
    rgb = np.full_like(pts, 0.5)
    bounds = (np.zeros(3, np.float32), np.array([2.0, 2.0, 1.0], np.float32))
    key = jax.random.key(0)
    cfg = model.PriorConfig()
    prior = model.init(pts, rgb, 400, key=key, scheme="data", bounds=bounds)
    ell = np.sqrt(np.diagonal(expfam.niw_expected_covariance(prior.space)[0])) / cfg.cov_scale
    np.testing.assert_allclose(ell, np.sqrt(4.0 / 400), rtol=0.06)
    fixed = model.init(pts, rgb, 400, key=key, scheme="data", bounds=bounds, length_scale=0.3)
    np.testing.assert_allclose(
        expfam.niw_expected_covariance(fixed.space)[0], (cfg.cov_scale * 0.3) ** 2 * np.eye(3),
        rtol=1e-5)
