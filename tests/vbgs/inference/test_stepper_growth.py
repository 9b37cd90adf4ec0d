"""A stepper whose reference grows (vbgs.inference.grow fills slots) is grown into a new one, equals a
freshly built one, and never recompiles its step."""

import jax
import numpy as np
import pytest

from vbgs.data.synthetic import object_scene
from vbgs.inference import grow, model, stepper
from vbgs.render.camera import unproject
from vbgs.render.splats import mixture_geometry


@pytest.fixture(scope="module")
def frames():
    scene = object_scene(size=24, n_train=5, n_test=1, seed=1)
    return [unproject(f.camera, f.rgb, f.depth) for f in scene.train]


K = 400


def _start(frames, config=model.PriorConfig()):
    """The growth rule and the empty state of a stream of ``frames``."""
    rule = grow.calibrate(frames[0][0], K, 0.3 * K, refine=0.05)
    return rule, grow.start_empty(frames[0][0], K, rule.cell, config)


@pytest.mark.parametrize(("assign", "estep", "config"), [
    ("prior", "sparse", model.PriorConfig()), ("prior", "dense", model.PriorConfig()),
    ("posterior", "sparse", model.PriorConfig()), ("posterior", "dense", model.PriorConfig()),
    # grown rows with their own (surface-aligned) scale matrices
    ("prior", "sparse", model.SURFACE_PRIOR), ("posterior", "dense", model.SURFACE_PRIOR)])
def test_a_grown_stepper_equals_a_fresh_one(frames, assign, estep, config, monkeypatch):
    # small row blocks: a frame's growth spans several, so the E[log pi] shift of the
    # rows between blocks is checked too (one block of 512 would cover all of K=400)
    monkeypatch.setattr(stepper, "ROW_BLOCK", 16)
    rule, state = _start(frames, config)
    size = max(len(f[0]) for f in frames)  # one padded size: one compiled step
    kept, n_grown = None, []
    for i, (xyz, rgb) in enumerate(frames):
        state, info = grow.grow(state, xyz, rgb, rule, key=jax.random.key(i), config=config)
        n_grown.append(info.n_new)
        if kept is None:
            kept = stepper.Stepper(state.prior, assign=assign, estep=estep, grows=True,
                                   max_points=size, config=config)
        else:
            kept = kept.grow(state.prior, info.slots)
        fresh = stepper.Stepper(state.prior, assign=assign, estep=estep, grows=True,
                                max_points=size, config=config)
        a, ainfo = kept(state, xyz, rgb)
        b, binfo = fresh(state, xyz, rgb)
        if assign == "prior":  # the terms themselves, row by row
            for got, want in zip(jax.tree.leaves(kept.fixed.reference),
                                 jax.tree.leaves(fresh.fixed.reference), strict=True):
                np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
        n = len(xyz)
        # sums of terms of ~1e2-1e3 nats that cancel to a few: float32 leaves ~1e-4 nats
        # (seen: 1.2e-4 on the dense E-step); a missed E[log pi] shift or a stale row
        # moves them by far more
        np.testing.assert_allclose(np.asarray(ainfo.point_loglik)[:n],
                                   np.asarray(binfo.point_loglik)[:n], rtol=1e-5, atol=5e-4)
        np.testing.assert_allclose(a.stats.count, b.stats.count, rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(a.posterior.space.mean, b.posterior.space.mean,
                                   rtol=1e-5, atol=1e-5)
        scale = np.abs(np.asarray(b.posterior.space.scale)).max()
        np.testing.assert_allclose(a.posterior.space.scale, b.posterior.space.scale,
                                   rtol=1e-4, atol=1e-4 * scale)  # float32 sums
        state = a
    assert sum(n > 0 for n in n_grown[1:]) >= 3  # the reference grew after the start
    assert float(state.stats.count.sum()) == pytest.approx(sum(len(f[0]) for f in frames),
                                                           rel=1e-4)


def test_growth_does_not_recompile_the_step(frames):
    rule, state = _start(frames)
    state, _ = grow.grow(state, *frames[0], rule, key=jax.random.key(0))
    step = stepper.Stepper(state.prior, estep="sparse", grows=True,
                           max_points=max(len(f[0]) for f in frames))
    # count from zero: other tests may already have compiled the sizes this one meets
    stepper._step.clear_cache()
    stepper._grown_first.clear_cache()
    stepper._grown_again.clear_cache()
    state, _ = step(state, *frames[0])  # compiles the step
    sizes = set()
    for i, (xyz, rgb) in enumerate(frames[1:], 1):
        state, info = grow.grow(state, xyz, rgb, rule, key=jax.random.key(i))
        step = step.grow(state.prior, info.slots)
        sizes.add(info.n_new)
        state, _ = step(state, xyz, rgb)
    assert len(sizes) > 1  # the frames grow different numbers of components...
    assert stepper._step._cache_size() == 1  # ...and the step is traced once
    assert stepper._grown_first._cache_size() == 1  # so is the row update
    assert stepper._grown_again._cache_size() <= 1  # (and its in-place form)


@pytest.mark.parametrize("estep", ["sparse", "dense"])
def test_rows_updated_in_place_equal_copied_ones_and_leave_the_old_stepper(
        frames, estep, monkeypatch):
    """Blocks after the first update the terms in place (donated): the same terms, to
    the bit, as each block copying them, and the stepper grown from keeps its own."""
    monkeypatch.setattr(stepper, "ROW_BLOCK", 16)
    rule, state = _start(frames)
    step = stepper.Stepper(state.prior, estep=estep, grows=True)
    before = jax.tree.map(np.array, step.fixed.reference)
    grown, info = grow.grow(state, *frames[0], rule, key=jax.random.key(0))
    assert info.n_new > 3 * 16  # several blocks
    new = step.grow(grown.prior, info.slots)
    want, alpha = step.fixed.reference, state.prior.alpha
    for block in stepper.row_blocks(info.slots):  # every block copied: the old way
        want = stepper._grown_first(want, alpha, grown.prior, block, estep,
                                    step.colour_noise)
        alpha = grown.prior.alpha
    for a, b in zip(jax.tree.leaves(new.fixed.reference), jax.tree.leaves(want), strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    for a, b in zip(jax.tree.leaves(step.fixed.reference), jax.tree.leaves(before),
                    strict=True):
        assert np.array_equal(np.asarray(a), b)  # not donated: still readable, unchanged


def test_a_growing_stepper_refuses_the_grid(frames):
    rule, state = _start(frames)
    prior = grow.grow(state, *frames[0], rule, key=jax.random.key(0))[0].prior
    with pytest.raises(ValueError, match="grid"):
        stepper.Stepper(prior, estep="sparse", search="grid", grows=True)
    fixed = stepper.Stepper(prior, estep="sparse", search="grid")
    with pytest.raises(ValueError, match="grows=True"):
        fixed.grow(prior, np.arange(3))
    wrong = grow.empty_prior(prior.n_components + 1, np.asarray(prior.origin), 1.0)
    with pytest.raises(ValueError, match="fills slots"):
        stepper.Stepper(prior, grows=True).grow(wrong, np.arange(3))


def test_row_blocks_cover_the_rows_in_fixed_blocks():
    rows = np.arange(3, 3 + stepper.ROW_BLOCK + 7)
    blocks = stepper.row_blocks(rows)
    assert [len(b) for b in blocks] == [stepper.ROW_BLOCK] * 2
    assert set(np.concatenate(blocks)) == set(rows)
    assert stepper.row_blocks(np.zeros(0, int)) == []


def _plane(rng, n, x0, z, colour):
    """``n`` points on the unit square ``x in [x0, x0 + 1], y in [0, 1]`` at depth ``z``."""
    xyz = np.stack([rng.uniform(x0, x0 + 1, n), rng.uniform(0, 1, n), np.full(n, z)], 1)
    return xyz.astype(np.float32), np.tile(np.float32(colour), (n, 1))


@pytest.mark.parametrize("reach", [None, 0.3])
def test_reach_keeps_a_spent_budget_off_a_depth_edge(reach):
    """A depth edge: plane A at z=0, plane B behind it at z=1 beyond A's x range. All K
    components sit on A (the budget is spent) when B arrives. Without ``reach``, B's points
    go to A's edge components, which stretch across the gap; with it (2 cells of 0.15),
    B's points are left out and counted, and every component stays on A."""
    rng = np.random.default_rng(0)
    a_xyz, a_rgb = _plane(rng, 3000, 0.0, 0.0, [0.8, 0.2, 0.2])
    b_xyz, b_rgb = _plane(rng, 3000, 1.0, 1.0, [0.2, 0.2, 0.8])
    prior = model.init(a_xyz, a_rgb, 60, key=jax.random.key(0), scheme="data")
    step = stepper.Stepper(prior, estep="sparse", search="kdtree", reach=reach)
    state = model.start(prior)
    a2_xyz, a2_rgb = _plane(rng, 3000, 0.0, 0.0, [0.8, 0.2, 0.2])
    state, first = step(state, a2_xyz, a2_rgb)
    state, last = step(state, np.concatenate([a_xyz, b_xyz]), np.concatenate([a_rgb, b_rgb]))
    means, covs = mixture_geometry(state.posterior)
    extent = np.sqrt(np.linalg.eigvalsh(np.asarray(covs, np.float64))[:, -1])  # [K]
    depth = np.sqrt(np.asarray(covs)[:, 2, 2])  # [K] spread along the gap
    if reach is None:
        assert first.learned is None and last.learned is None  # no reach: every point
        assert depth.max() > 0.25  # some component spans a quarter of the gap or more
    else:
        assert first.learned.all()  # A within reach
        np.testing.assert_array_equal(last.learned, np.arange(6000) < 3000)  # B left out
        assert depth.max() < 0.05 and extent.max() < 0.3  # flat on A (prior floor ~0.01)
        assert np.abs(np.asarray(means)[:, 2]).max() < 0.01
        np.testing.assert_allclose(float(state.stats.count.sum()), 2 * 3000, rtol=1e-4)  # A, twice


def test_reach_needs_the_kdtree_search():
    rng = np.random.default_rng(1)
    prior = model.init(*_plane(rng, 200, 0.0, 0.0, [0.5, 0.5, 0.5]), 10,
                       key=jax.random.key(0), scheme="data")
    for reach, kwargs in ((0.3, {"estep": "dense"}), (0.3, {"estep": "sparse", "search": "grid"}),
                          (-1.0, {"estep": "sparse", "search": "kdtree"})):
        with pytest.raises(ValueError, match="reach"):
            stepper.Stepper(prior, reach=reach, **kwargs)
