"""A frame's points reach growth with their pixels (vbgs.mapping.mapper: _prepare,
pixel_grid), where their patches are found on the pixel grid
(vbgs.inference.pixel_patches) rather than in a KD-tree over the batch."""

import sys

import jax
import numpy as np

from vbgs.data.scene import Frame
from vbgs.inference.pixel_patches import PixelGrid
from vbgs.mapping import BudgetConfig, Config, init, update
from vbgs.render.camera import from_fov, look_at, unproject, valid_depth

mapper = sys.modules["vbgs.mapping.mapper"]  # the module (vbgs.mapping.mapper is a function)
W, H = 48, 32


def tilted_frame() -> Frame:
    """A wall seen obliquely from 2 units, a colour ramp, a few pixels without depth."""
    cam = from_fov(W, H, 1.2, look_at((0.8, -2.0, 0.5), (0.0, 0.0, 0.5)))
    u, v = np.meshgrid(np.linspace(0, 1, W), np.linspace(0, 1, H))
    rgb = np.stack([u, v, 0.5 * (u + v)], -1).astype(np.float32)
    # depth of the plane y = 0 along each pixel's ray
    pose = np.asarray(cam.pose, np.float64)
    x = (np.arange(W) + 0.5 - float(cam.cx)) / float(cam.fx)
    y = (np.arange(H) + 0.5 - float(cam.cy)) / float(cam.fy)
    rays = np.stack(np.broadcast_arrays(x[None, :], y[:, None], 1.0), -1) @ pose[:3, :3].T
    depth = (-pose[1, 3] / rays[..., 1]).astype(np.float32)
    depth[5:9, 10:14] = 0.0  # a hole: the points' raster order skips it
    return Frame(rgb, depth, cam)


def test_each_point_keeps_its_pixel_through_the_budget():
    frame = tilted_frame()
    full, _ = unproject(frame.camera, frame.rgb, frame.depth)
    full_pixel = np.flatnonzero(valid_depth(frame.depth))
    for points in (0, 400):  # every pixel; every 2nd pixel a side
        config = Config(components=50, budget=BudgetConfig(points=points))
        state = init(config, key=jax.random.key(0))
        _, p = mapper._prepare(state, frame, config, None)
        assert len(p.pixel) == len(p.xyz) < (W * H if points == 0 else 400 + 1)
        np.testing.assert_array_equal(p.xyz, full[np.searchsorted(full_pixel, p.pixel)])
        grid = mapper.pixel_grid(p.pixel, frame.camera, p.footprint, config)
        assert grid.shape == (H, W) and grid.step == (1 if points == 0 else 2)
    assert mapper.pixel_grid(None, frame.camera, p.footprint, config) is None  # bare points


def test_a_frame_grows_on_its_pixel_grid_as_on_the_kd_tree(monkeypatch):
    """The grown components of a wall seen obliquely: the same means and (flattened)
    scales whether the seeds' patches come from the pixel grid or from the KD-tree."""
    frame = tilted_frame()
    config = Config(components=60)
    seen = []
    grow_components = mapper.grow_components

    def spy(*args):
        seen.append(args[-1])
        return grow_components(*args)

    monkeypatch.setattr(mapper, "grow_components", spy)
    by_pixel, _ = update(init(config, key=jax.random.key(0)), frame, config)
    assert isinstance(seen[-1], PixelGrid)
    monkeypatch.setattr(mapper, "pixel_grid", lambda *a: None)
    by_tree, _ = update(init(config, key=jax.random.key(0)), frame, config)
    assert seen[-1] is None
    a, b = by_pixel.mixture.prior.space, by_tree.mixture.prior.space
    np.testing.assert_allclose(np.asarray(a.mean), np.asarray(b.mean), atol=1e-6)
    np.testing.assert_allclose(np.asarray(a.scale), np.asarray(b.scale), rtol=1e-4,
                               atol=1e-6 * float(np.abs(np.asarray(b.scale)).max()))
    scale = np.asarray(a.scale)[np.asarray(by_pixel.mixture.prior.alpha) > 1e-3]
    flat = np.linalg.eigvalsh(scale)
    assert (flat[:, 0] < 0.05 * flat[:, 2]).all()  # flattened along the wall's normal
