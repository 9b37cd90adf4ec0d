"""The compiled stream stepper and the device grid search against their slow references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.data.synthetic import object_scene
from vbgs.inference import grid, model, stepper
from vbgs.inference.candidates import nearest_components
from vbgs.render.camera import unproject


@pytest.fixture(scope="module")
def scene_points():
    scene = object_scene(size=32, n_train=6, n_test=1, seed=0)
    pts = [unproject(f.camera, f.rgb, f.depth) for f in scene.train]
    xyz = np.concatenate([p[0] for p in pts])
    rgb = np.concatenate([p[1] for p in pts])
    prior = model.init(xyz, rgb, 600, key=jax.random.key(0), scheme="data", bounds=scene.bounds)
    return prior, pts


def _grid_candidates(means, x, n_candidates):
    spec = grid.plan(means, n_candidates)
    lists = grid.build(means, spec)
    w = jnp.ones((x.shape[0],), jnp.float32)
    return np.asarray(jax.jit(grid.search, static_argnums=4)(lists, means, jnp.asarray(x), w,
                                                             spec))


def test_grid_candidates_equal_the_kdtree_on_scene_points(scene_points):
    prior, pts = scene_points
    x = np.asarray(pts[2][0] - np.asarray(prior.origin), np.float32)
    got = _grid_candidates(prior.space.mean, x, 16)
    want = nearest_components(prior.space.mean, x, 16)
    np.testing.assert_array_equal(np.sort(got, 1), np.sort(want, 1))


@pytest.mark.parametrize("d", [2, 3])
def test_grid_candidates_exact_inside_and_outside_the_box(d):
    """Points far outside the means' box take the exhaustive fallback; all are exact."""
    rng = np.random.default_rng(d)
    means = jnp.asarray(rng.uniform(-1, 1, (500, d)), jnp.float32)
    x = np.concatenate([rng.uniform(-1, 1, (300, d)), rng.uniform(-4, 4, (40, d))])
    x = x.astype(np.float32)
    got = _grid_candidates(means, x, 8)
    d2 = ((x[:, None] - np.asarray(means)[None]) ** 2).sum(-1)
    want = np.argsort(d2, 1)[:, :8]
    np.testing.assert_array_equal(np.sort(got, 1), np.sort(want, 1))


def test_cell_lists_hold_every_point_s_nearest(scene_points):
    """The stored list of a point's cell is a superset of its C nearest (the proof's claim)."""
    prior, pts = scene_points
    means = np.asarray(prior.space.mean)
    spec = grid.plan(means, 16)
    lists = grid.build(means, spec)
    x = pts[4][0] - np.asarray(prior.origin)
    ci = np.floor((x - np.asarray(spec.lo)) / spec.cell).astype(int)
    rows = np.asarray(lists.row)[np.ravel_multi_index(tuple(ci.T), spec.dims)]
    listed = rows >= 0
    assert listed.mean() > 0.95
    near = nearest_components(means, x, 16)
    ids = np.asarray(lists.ids)
    live = np.isfinite(np.asarray(lists.means)[:, 0, :])
    for i in np.flatnonzero(listed):
        assert set(near[i]) <= set(ids[rows[i]][live[rows[i]]])


@pytest.mark.parametrize(("assign", "estep", "search"), [
    ("prior", "dense", "auto"), ("prior", "sparse", "grid"), ("prior", "sparse", "kdtree"),
    ("posterior", "sparse", "auto"), ("posterior", "dense", "auto")])
def test_stepper_equals_model_update(scene_points, assign, estep, search):
    prior, pts = scene_points
    step = stepper.Stepper(prior, assign=assign, estep=estep, search=search)
    fast, slow = model.start(prior), model.start(prior)
    for xyz, rgb in pts[:3]:
        fast, finfo = step(fast, xyz, rgb)
        slow, sinfo = model.update(slow, xyz, rgb, assign=assign, estep=estep)
        n = len(xyz)
        # posterior assignment carries float32 rounding from batch to batch (below); a
        # point's log-likelihood is a sum of terms of ~1e2-1e3 nats (quadratic forms,
        # log-determinants) that cancel to a few nats, so float32 leaves ~1e-4 nats of
        # it, more where padding changes the summation order (seen: 1.2e-4)
        np.testing.assert_allclose(np.asarray(finfo.point_loglik)[:n], sinfo.point_loglik,
                                   rtol=1e-5 if assign == "prior" else 1e-4,
                                   atol=1e-4 if assign == "prior" else 5e-4)
        np.testing.assert_allclose(finfo.elbo, sinfo.elbo, rtol=1e-5)
    # posterior assignment carries float32 rounding (padding changes the summation
    # order) from batch to batch, so counts agree to 1e-3 of a point there
    np.testing.assert_allclose(fast.stats.count, slow.stats.count, rtol=1e-5,
                               atol=1e-4 if assign == "prior" else 1e-3)
    np.testing.assert_allclose(fast.posterior.space.mean, slow.posterior.space.mean,
                               rtol=1e-5, atol=1e-5)
    scale = np.abs(np.asarray(slow.posterior.space.scale)).max()  # float32 sums: relative
    np.testing.assert_allclose(fast.posterior.space.scale, slow.posterior.space.scale,
                               rtol=1e-4, atol=1e-4 * scale)


def test_stepper_compiles_once_for_a_stream(scene_points):
    prior, pts = scene_points
    step = stepper.Stepper(prior, estep="sparse", search="grid",
                           max_points=max(len(p[0]) for p in pts))
    before = stepper._step._cache_size()
    state = model.start(prior)
    for xyz, rgb in pts:
        state, _ = step(state, xyz, rgb)
    assert len({len(p[0]) for p in pts}) > 1  # the frames differ in size...
    assert stepper._step._cache_size() - before <= 1  # ...and share one compiled step


def test_padding_that_follows_the_batch_pays_for_its_points(scene_points):
    """``follow=True``: a batch is padded to the power of two that holds it (at least
    FOLLOW_MIN), smaller after a larger one, with the statistics of the padding-that-only-
    grows stepper."""
    prior, pts = scene_points
    grows = stepper.Stepper(prior, estep="sparse", search="kdtree")
    follows = stepper.Stepper(prior, estep="sparse", search="kdtree", follow=True)
    assert [follows.padded_size(n) for n in (1, 4096, 4097, 70000, 5000)] == \
        [4096, 4096, 8192, 131072, 8192]
    assert grows.padded_size(70000) == model.bucket_size(int(70000 * stepper.GROWTH))
    assert grows.padded_size(5000) == grows.padded_size(70000)  # it only grows
    a, b = model.start(prior), model.start(prior)
    xyz = np.concatenate([pts[0][0], pts[1][0]])
    rgb = np.concatenate([pts[0][1], pts[1][1]])
    for x, c in ((xyz, rgb), pts[2]):  # a large batch, then a small one
        a, _ = grows(a, x, c)
        b, _ = follows(b, x, c)
    np.testing.assert_allclose(b.stats.count, a.stats.count, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(b.posterior.space.mean, a.posterior.space.mean, rtol=1e-5,
                               atol=1e-5)


def test_stepper_refuses_unknown_settings(scene_points):
    prior, _ = scene_points
    with pytest.raises(ValueError, match="candidate search"):
        stepper.Stepper(prior, search="octree")
    with pytest.raises(ValueError, match="E-step"):
        stepper.Stepper(prior, estep="fast")
