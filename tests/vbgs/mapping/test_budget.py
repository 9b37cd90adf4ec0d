"""A frame's point budget (vbgs.mapping.budget): the kept points fit the budget and,
weighted, keep the sufficient statistics unbiased on a known plane."""

import jax
import numpy as np
import pytest

from vbgs.data.scene import Frame
from vbgs.inference import model
from vbgs.inference.stepper import Stepper
from vbgs.mapping import BudgetConfig, Config, budget, init, update
from vbgs.render.camera import from_fov, look_at, unproject

W, H = 48, 32


def plane_frame() -> Frame:
    """A wall at y = 0 seen head-on from 2 units (depth 2 at every pixel), a colour ramp."""
    cam = from_fov(W, H, 1.2, look_at((0.0, -2.0, 0.5), (0.0, 0.0, 0.5)))
    u, v = np.meshgrid(np.linspace(0, 1, W), np.linspace(0, 1, H))
    rgb = np.stack([u, v, 0.5 * (u + v)], -1).astype(np.float32)
    return Frame(rgb, np.full((H, W), 2.0, np.float32), cam)


def test_stride_fits_the_budget():
    assert budget.stride(640, 480, 0) == 1  # no budget
    assert budget.stride(128, 128, 20000) == 1  # today's frames fit a 20k budget
    assert budget.stride(640, 480, 20000) == 4  # 160 x 120 = 19200 points
    assert budget.stride(640, 480, 16384) == 5
    for w, h, p in ((640, 480, 19200), (641, 479, 1000), (7, 5, 3)):
        s = budget.stride(w, h, p)
        assert -(-w // s) * -(-h // s) <= p < -(-w // (s - 1)) * -(-h // (s - 1)) or s == 1


def test_thin_keeps_a_lattice_within_the_budget():
    f = plane_frame()
    depth, weight = budget.thin(f.depth, 400, key=jax.random.key(0), weighted=True)
    s = budget.stride(W, H, 400)
    assert s == 2 and len(weight) == np.count_nonzero(depth) <= 400
    np.testing.assert_array_equal(weight, 4.0)
    assert budget.thin(f.depth, W * H, key=jax.random.key(0))[1] is None  # fits: untouched
    with pytest.raises(ValueError, match="offset"):
        budget.lattice(f.depth, 2, (2, 0))


def _stats(prior, frame, depth, weight):
    xyz, rgb = unproject(frame.camera, frame.rgb, depth)
    step = Stepper(prior, assign="prior", estep="dense")
    return step(model.start(prior), xyz, rgb, weight=weight)[0].stats


def test_weighted_statistics_are_unbiased_on_a_plane():
    """Under a fixed reference the statistics are sums over points: their mean over every
    offset of the lattice equals learning every point (exactly, up to rounding)."""
    f = plane_frame()
    xyz, rgb = unproject(f.camera, f.rgb, f.depth)
    prior = model.init(xyz, rgb, 6, key=jax.random.key(1), scheme="data")
    full = _stats(prior, f, f.depth, None)
    s = 3
    runs = [_stats(prior, f, *budget.lattice(f.depth, s, (oy, ox), weighted=True))
            for oy in range(s) for ox in range(s)]
    for name in ("count", "sum_x", "sum_xx", "sum_c"):
        mean = np.mean([np.asarray(getattr(r, name)) for r in runs], 0)
        np.testing.assert_allclose(mean, np.asarray(getattr(full, name)), rtol=2e-4,
                                   atol=2e-3, err_msg=name)
    # one offset alone: counts within 15% of the full frame's (one of nine pixels kept)
    one = np.asarray(runs[4].count)
    np.testing.assert_allclose(one, np.asarray(full.count), rtol=0.15)


def test_mapper_posterior_with_a_budget_matches_every_point():
    """Through vbgs.mapping on the plane, a fixed start: a budget of a sixteenth of the pixels
    (a lattice of step 4) moves the posterior means by under two pixels (measured 1.35)
    and keeps the counts; unweighted, the counts fall sixteenfold."""
    f = plane_frame()
    xyz, rgb = unproject(f.camera, f.rgb, f.depth)
    prior = model.init(xyz, rgb, 6, key=jax.random.key(1), scheme="data")

    def learn(points, weighted=True):
        config = Config(components=6, estep="dense", budget=BudgetConfig(points, weighted))
        state, _ = update(init(config, key=jax.random.key(2), prior=prior), f, config)
        return state.mixture

    full, thin, plain = learn(0), learn(W * H // 16), learn(W * H // 16, weighted=False)
    pixel = 2.0 / float(f.camera.fx)  # a pixel's side on the wall: 0.056 units
    shift = np.abs(np.asarray(thin.posterior.space.mean) - np.asarray(full.posterior.space.mean))
    assert shift.max() < 2 * pixel
    counts = np.asarray(full.stats.count)
    np.testing.assert_allclose(np.asarray(thin.stats.count).sum(), counts.sum(), rtol=0.02)
    np.testing.assert_allclose(np.asarray(plain.stats.count).sum() * 16, counts.sum(), rtol=0.02)


def test_lattice_camera_sees_each_kept_pixel_at_its_own_centre():
    """budget.on_lattice: a kept pixel's ray through the thinned frame's camera is its ray
    through the full camera, for every offset; the lattice image is the same size for all."""
    from vbgs.render.pixels import pixel_rays
    cam = plane_frame().camera
    full = pixel_rays(H, W, cam.fx, cam.fy, cam.cx, cam.cy).reshape(-1, 3)
    for offset in ((0, 0), (1, 2), (2, 1)):
        depth, _ = budget.lattice(np.ones((H, W), np.float32), 3, offset)
        pixel = np.flatnonzero(depth)
        sub, at = budget.on_lattice(cam, pixel, 3)
        assert (sub.width, sub.height) == (16, 11) and at.max() < sub.width * sub.height
        rays = pixel_rays(sub.height, sub.width, sub.fx, sub.fy, sub.cx, sub.cy).reshape(-1, 3)
        np.testing.assert_allclose(rays[at], full[pixel], atol=1e-12)
    assert budget.on_lattice(cam, pixel, 1)[0] is cam
    with pytest.raises(ValueError, match="one lattice of stride 3"):
        budget.on_lattice(cam, np.array([0, 1]), 3)


def test_thinned_frame_learned_on_its_lattice_by_projection():
    """The projective search laying a thinned frame out on its lattice's own image
    (budget.on_lattice) learns as well as laid out on the full image, where three in four
    tiles' slots are empty: tiles of the same side on the wall (8 pixels, 4 of the
    lattice's), each point's counts no farther from every component's (the KD-tree
    listing all 12) than the full layout's are (measured 4.6 either way) and all points
    learned. Not equal: the tiles' edges lie half a pixel apart, so a few points near
    them list other components."""
    f = plane_frame()
    xyz, rgb = unproject(f.camera, f.rgb, f.depth)
    prior = model.init(xyz, rgb, 12, key=jax.random.key(1), scheme="data")
    depth, _ = budget.lattice(f.depth, 2, (1, 0))
    pts, colours = unproject(f.camera, f.rgb, depth)
    pixel = np.flatnonzero(depth)

    def counts(camera=None, at=None, search="kdtree"):
        stepper = Stepper(prior, estep="sparse", n_candidates=12, search=search, spacing=5.0)
        stats = stepper(model.start(prior), pts, colours, camera=camera, pixel=at)[0].stats
        assert search == "kdtree" or stepper.tiling.tile * f.camera.width == 8 * camera.width
        return np.asarray(stats.count)

    every = counts()
    full = counts(f.camera, pixel, "projective")
    sub = counts(*budget.on_lattice(f.camera, pixel, 2), "projective")
    np.testing.assert_allclose(sub.sum(), len(pts), rtol=1e-5)
    assert np.abs(sub - every).max() <= np.abs(full - every).max() + 0.5


def test_auto_search_projects_frames_larger_than_320x240():
    """``search="auto"`` (the default): the KD-tree for frames up to 320 x 240 (fit-scene's
    128 px frames keep their records), the projective search above, bare points always
    the KD-tree; an explicit choice is kept."""
    from vbgs.mapping.config import PROJECTIVE_PIXELS, frame_search

    pose = look_at((0.0, -2.0, 0.5), (0.0, 0.0, 0.5))
    assert PROJECTIVE_PIXELS == 320 * 240
    assert frame_search("auto", from_fov(320, 240, 1.2, pose)) == "kdtree"
    assert frame_search("auto", from_fov(322, 240, 1.2, pose)) == "projective"
    assert frame_search("auto", None) == "kdtree"
    assert frame_search("kdtree", from_fov(640, 480, 1.2, pose)) == "kdtree"
    assert frame_search("projective", from_fov(48, 32, 1.2, pose)) == "projective"
    assert Config().search == "auto"

    def learned_by(w, h):
        cam = from_fov(w, h, 1.2, pose)
        rgb = np.full((h, w, 3), 0.5, np.float32)
        state = init(Config(components=2000), key=jax.random.key(0))
        state, _ = update(state, Frame(rgb, np.full((h, w), 2.0, np.float32), cam), Config(
            components=2000))
        return state.stepper.search

    assert learned_by(48, 32) == "kdtree"
    assert learned_by(400, 300) == "projective"
