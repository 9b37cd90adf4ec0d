"""Growth's patches on a frame's pixel grid (vbgs.inference.pixel_patches) against the
KD-tree's nearest points (the reference), and the masked quadric they are fitted with."""

import numpy as np
import pytest

from vbgs.inference import grow, pixel_patches, quadric
from vbgs.inference.pixel_patches import PixelGrid

F = 150.0  # focal length in pixels

# Normals agree within this angle (radians): the patches are fitted in float32.
ANGLE = 5e-4


def _rays(h, w):
    v, u = np.mgrid[:h, :w] + 0.5
    return np.stack([(u - w / 2) / F, (v - h / 2) / F, np.ones((h, w))], -1)  # [h, w, 3]


def _plane_depth(h, w, normal, offset):
    """z-depth of the plane ``normal . X = offset`` seen from the origin."""
    return offset / (_rays(h, w) @ np.asarray(normal, np.float64))


def _sphere_depth(h, w, centre, radius):
    """z-depth of the near side of a sphere (0 where the ray misses it)."""
    r = _rays(h, w)
    a, b = (r * r).sum(-1), -2 * (r @ np.asarray(centre))
    c = np.dot(centre, centre) - radius**2
    disc = b * b - 4 * a * c
    return np.where(disc > 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), 0.0)


def _frame(depth, step=1):
    """The frame's points ``[n, 3]`` (camera at the origin, raster order) and its grid."""
    h, w = depth.shape
    ok = depth > 0
    if step > 1:
        lattice = np.zeros_like(ok)
        lattice[1::step, 1::step] = True
        ok &= lattice
    x = _rays(h, w)[ok] * depth[ok][:, None]
    return x, PixelGrid(np.flatnonzero(ok), (h, w), step, depth[ok] / F, np.zeros(3))


def _angle(a, b):
    """Degrees between the lines along ``a`` and ``b`` ``[m, 3]`` (a normal's sign is free)."""
    cos = np.abs((a * b).sum(1)) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    return np.degrees(np.arccos(np.minimum(cos, 1.0)))


def _inside(grid, margin=6):
    """Points at least ``margin`` lattice steps from the image's border."""
    h, w = grid.shape
    r, c = grid.flat // w, grid.flat % w
    m = margin * grid.step
    return np.flatnonzero((r >= m) & (r < h - m) & (c >= m) & (c < w - m))


TILT = np.array([np.sin(np.radians(50)), 0.0, -np.cos(np.radians(50))])  # 50 deg off the view


def test_disc_holds_the_wanted_count_nearest_first():
    assert len(pixel_patches.disc(48)) == 49 and len(pixel_patches.disc(12)) == 13
    assert len(pixel_patches.disc(120)) == 121 and len(pixel_patches.disc(30)) == 37
    off = pixel_patches.disc(48)
    assert (off[0] == 0).all() and np.abs(off).max() == 4
    d2 = (off**2).sum(1)
    assert (np.diff(d2) >= 0).all() and d2.max() == 16


def test_a_tilted_plane_gives_the_kd_tree_s_normals_and_seeds():
    depth = _plane_depth(90, 120, TILT, -2.0)
    x, grid = _frame(depth)
    chosen = _inside(grid)[::211]
    want = np.tile(TILT, (len(chosen), 1))
    kd = grow.local_normals(x, chosen)
    px = grow.local_normals(x, chosen, pixel=grid)
    assert _angle(px, want).max() < ANGLE and _angle(kd, want).max() < ANGLE
    # noisy depth (half a pixel footprint along each ray): seeds slid back onto the plane
    # as far as the KD-tree's, normals as near the plane's (both tilted by the noise)
    rng = np.random.default_rng(1)
    chosen = _inside(grid)[::53]
    want = np.tile(TILT, (len(chosen), 1))
    sigma = 0.5 * grid.footprint
    ray = sigma[:, None] * x / np.linalg.norm(x, axis=1, keepdims=True)
    noisy = x + rng.standard_normal(len(x))[:, None] * ray
    grid = grid._replace(footprint=noisy[:, 2] / F)  # the measured depth's
    n_kd, s_kd = grow.seeds_on_patches(noisy, chosen, ray)
    n_px, s_px = grow.seeds_on_patches(noisy, chosen, ray, pixel=grid)
    a_kd, a_px = _angle(n_kd, want).mean(), _angle(n_px, want).mean()  # 1.35, 1.39 deg
    assert a_px < 2.0 and a_px < 1.2 * a_kd
    off = np.abs(noisy[chosen] @ TILT + 2.0) / sigma[chosen]  # from the plane, in sigma
    off_kd = np.abs(s_kd @ TILT + 2.0) / sigma[chosen]
    off_px = np.abs(s_px @ TILT + 2.0) / sigma[chosen]
    assert off_px.mean() < 0.3 * off.mean() and off_px.mean() < 1.2 * off_kd.mean()
    gap = np.linalg.norm(s_px - s_kd, axis=1) / sigma[chosen]  # 0.14 sigma
    assert gap.mean() < 0.2 and gap.max() < 0.8


def test_a_sphere_gives_the_kd_tree_s_normals():
    depth = _sphere_depth(120, 160, np.array([0.0, 0.0, 3.0]), 1.0)
    x, grid = _frame(depth)
    chosen = _inside(grid)[::97]
    # up to some 60 degrees from head-on: nearer the rim the KD-tree's ball and the pixel
    # window, stretched along the slope, see different parts of the curve (both off)
    chosen = chosen[depth[depth > 0][chosen] < 2.2]
    radial = x[chosen] - np.array([0.0, 0.0, 3.0])
    for k in (12, 48):
        kd = grow.local_normals(x, chosen, k)
        px = grow.local_normals(x, chosen, k, pixel=grid)
        assert _angle(px, kd).max() < 1.0 and _angle(px, kd).mean() < 0.3  # 0.29, 0.16 at 12
        assert _angle(px, radial).mean() < 0.2 and _angle(kd, radial).mean() < 0.2
    ray = 1e-3 * x / np.linalg.norm(x, axis=1, keepdims=True)  # exact depth, a noise model
    n_kd, s_kd = grow.seeds_on_patches(x, chosen, ray)
    n_px, s_px = grow.seeds_on_patches(x, chosen, ray, pixel=grid)
    assert _angle(n_px, n_kd).max() < 1.0
    assert np.abs(np.linalg.norm(radial, axis=1) - 1.0).max() < 1e-6
    # the quadric leaves exact points where they are on both paths
    assert np.abs(np.linalg.norm(s_px - [0, 0, 3.0], axis=1) - 1.0).max() < 1e-5
    assert np.abs(np.linalg.norm(s_kd - [0, 0, 3.0], axis=1) - 1.0).max() < 1e-5


def test_a_thinned_frame_steps_its_windows_by_the_stride():
    depth = _plane_depth(90, 120, TILT, -2.0)
    x, grid = _frame(depth, step=3)
    chosen = _inside(grid)[::17]
    idx, weight = pixel_patches.window(x, chosen, grid, 48)
    assert (weight.sum(1) == 48).all()  # the wanted count, every one a point of the plane
    assert (np.abs(grid.flat[idx] - grid.flat[chosen][:, None]) % 3 == 0).all()
    px = grow.local_normals(x, chosen, 48, pixel=grid)
    assert _angle(px, np.tile(TILT, (len(chosen), 1))).max() < ANGLE


def _box_before_wall():
    """A wall 3 m away tilted 20 degrees, a box face 1.5 m away tilted 35 degrees the
    other way, covering the image's left half: a depth step at the box's edge."""
    h, w = 80, 120
    wall_n = np.array([np.sin(np.radians(20)), 0.0, -np.cos(np.radians(20))])
    box_n = np.array([-np.sin(np.radians(35)), 0.0, -np.cos(np.radians(35))])
    depth = _plane_depth(h, w, wall_n, -3.0)
    box = _plane_depth(h, w, box_n, -1.5)
    depth[:, : w // 2] = box[:, : w // 2]
    return depth, wall_n, box_n


def test_a_seed_on_the_foreground_s_edge_takes_the_foreground_s_normal():
    depth, wall_n, box_n = _box_before_wall()
    x, grid = _frame(depth)
    h, w = depth.shape
    rows = np.arange(10, h - 10, 7)
    edge = np.searchsorted(grid.flat, rows * w + w // 2 - 1)  # the box's last column
    assert (grid.flat[edge] % w == w // 2 - 1).all()
    for k in (12, 48):
        idx, weight = pixel_patches.window(x, edge, grid, k)
        wall = grid.flat[idx] % w >= w // 2  # the wall's pixels
        assert not (weight.astype(bool) & wall).any()  # none of the wall kept
        px = grow.local_normals(x, edge, k, pixel=grid)
        kd = grow.local_normals(x, edge, k)
        assert _angle(px, np.tile(box_n, (len(edge), 1))).max() < ANGLE
        assert _angle(kd, np.tile(box_n, (len(edge), 1))).max() < ANGLE
    # the wall's first column, beside the box: the wall's normal (its points nearer the
    # camera in the window are the box's, far in 3-D)
    wall_edge = np.searchsorted(grid.flat, rows * w + w // 2)
    px = grow.local_normals(x, wall_edge, 48, pixel=grid)
    assert _angle(px, np.tile(wall_n, (len(rows), 1))).max() < ANGLE


def test_a_thin_pole_before_a_wall_keeps_none_of_the_wall():
    """A pole 3 pixels wide: its windows hold fewer of its points than wanted, and the
    wall's points, nearest after them, are masked: the pole's own (tilted) normal."""
    depth, wall_n, box_n = _box_before_wall()
    h, w = depth.shape
    pole = np.zeros_like(depth, bool)
    pole[:, 40:43] = True
    depth = np.where(pole, _plane_depth(h, w, box_n, -1.5), _plane_depth(h, w, wall_n, -3.0))
    x, grid = _frame(depth)
    rows = np.arange(10, h - 10, 5)
    seeds = np.searchsorted(grid.flat, rows * w + 41)
    for k in (12, 48):
        idx, weight = pixel_patches.window(x, seeds, grid, k)
        on_pole = pole.ravel()[grid.flat[idx]]
        assert not (weight.astype(bool) & ~on_pole).any()
        assert (weight.sum(1) == min(k, 39)).all()  # 13 rows of 3 within 6.1 pixels
        px = grow.local_normals(x, seeds, k, pixel=grid)
        assert _angle(px, np.tile(box_n, (len(seeds), 1))).max() < ANGLE
        ray = 1e-3 * x / np.linalg.norm(x, axis=1, keepdims=True)  # a noise model
        n, s = grow.seeds_on_patches(x, seeds, ray, k, pixel=grid)
        assert _angle(n, np.tile(box_n, (len(seeds), 1))).max() < 1e-3
        np.testing.assert_allclose(s, x[seeds], atol=1e-6)


def test_a_window_of_too_few_points_keeps_the_measured_point_and_its_ray():
    """A speck: a pixel alone with one neighbour in front of a far wall (exact normals
    along the viewing ray; measured seeds at the point itself, normal along the ray)."""
    depth = _plane_depth(40, 40, np.array([0.0, 0.0, -1.0]), -5.0)
    depth[20, 20] = depth[20, 21] = 1.0  # two points of a speck 4 m before the wall
    x, grid = _frame(depth)
    speck = np.array([20 * 40 + 20, 20 * 40 + 21, 10 * 40 + 10])  # flat == index here
    _, weight = pixel_patches.window(x, speck, grid, 48)
    np.testing.assert_array_equal(weight.sum(1), [2, 2, 48])
    view = x[speck] / np.linalg.norm(x[speck], axis=1, keepdims=True)
    normal = grow.local_normals(x, speck, 48, pixel=grid)
    assert _angle(normal[:2], view[:2]).max() < 1e-9
    assert _angle(normal[2:], np.array([[0.0, 0.0, 1.0]])).max() < ANGLE  # the wall's
    ray = 0.01 * x / np.linalg.norm(x, axis=1, keepdims=True)
    noisy = x + 0.5 * ray
    normal, seeds = grow.seeds_on_patches(noisy, speck, ray, pixel=grid)
    np.testing.assert_array_equal(seeds[:2], noisy[speck[:2]])
    assert _angle(normal[:2], view[:2]).max() < 1e-9
    assert _angle(normal[2:], np.array([[0.0, 0.0, 1.0]])).max() < 0.05  # bent by the shift


def test_a_masked_point_counts_for_nothing():
    """The masked quadric of a patch equals that of its kept points alone (the KD path's
    formula, all weights 1, on the subset): a plane below QUADRIC_MIN_POINTS kept."""
    rng = np.random.default_rng(3)
    a, b = rng.uniform(-1, 1, size=(2, 300))
    x = np.stack([a, b, 0.3 * a * a - 0.2 * a * b + 0.1 * b + 0.01 * rng.normal(size=300)],
                 -1)
    ray = 0.01 * rng.normal(size=(300, 3))
    chosen = np.array([0, 1, 2])
    idx = np.stack([np.r_[0, rng.choice(np.arange(3, 300), 47, replace=False)],
                    np.r_[1, rng.choice(np.arange(3, 300), 47, replace=False)],
                    np.r_[2, rng.choice(np.arange(3, 300), 47, replace=False)]])
    weight = (rng.uniform(size=idx.shape) < 0.6).astype(float)
    weight[:, 0] = 1.0
    weight[2, 8:] = 0.0  # 8 kept: a plane
    normal, height = quadric.quadric_patches(x, chosen, 0, ray, index=idx, weight=weight)
    for m in range(3):
        keep = idx[m][weight[m] > 0]
        sub = x[keep]
        n1, h1 = quadric.quadric_patches(sub, np.array([0]), len(keep), ray[keep],
                                         index=np.arange(len(keep))[None])
        np.testing.assert_allclose(normal[m], n1[0], rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(height[m], h1[0], rtol=1e-4, atol=1e-6)
    assert len(idx[2][weight[2] > 0]) < quadric.QUADRIC_MIN_POINTS


def test_the_images_hold_each_point_at_its_padded_pixel_and_refuse_more_than_the_lattice():
    depth = _plane_depth(30, 40, TILT, -2.0)
    x, grid = _frame(depth, step=2)
    ray = np.tile([0.0, 0.0, 0.01], (len(x), 1))
    im = pixel_patches.images(x, grid, 3, ray)
    h, w = grid.shape
    at = (grid.flat // w + 3) * im.width + grid.flat % w + 3
    index = np.asarray(im.index)
    assert index.shape == ((h + 6) * (w + 6),) and (index[at] == np.arange(len(x))).all()
    assert (np.delete(index, at) == -1).all()  # the rest, the pad among it, hold nothing
    assert np.array_equal(np.asarray(im.xyz)[at], x.astype(np.float32))
    assert np.array_equal(np.asarray(im.noise)[at], ray.astype(np.float32))
    assert not np.asarray(im.xyz)[np.delete(np.arange(len(index)), at)].any()
    with pytest.raises(ValueError, match="lattice of step 2"):
        pixel_patches.images(np.zeros((15 * 20 + 1, 3)), grid, 3)
