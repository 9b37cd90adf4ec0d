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
