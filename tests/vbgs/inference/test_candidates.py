"""Sparse E-step against the dense reference; 3-D streaming order invariance."""

import jax
import numpy as np
import pytest

from vbgs.data.synthetic import object_scene
from vbgs.inference import model
from vbgs.inference.candidates import nearest_components
from vbgs.render.camera import unproject


@pytest.fixture(scope="module")
def frames():
    scene = object_scene(size=32, n_train=8, n_test=1, seed=0)
    return scene, [unproject(f.camera, f.rgb, f.depth) for f in scene.train]


def _prior(frames, k=400, scheme="data"):
    scene, pts = frames
    xyz = np.concatenate([p[0] for p in pts])
    rgb = np.concatenate([p[1] for p in pts])
    return model.init(xyz, rgb, k, key=jax.random.key(0), scheme=scheme, bounds=scene.bounds)


def test_nearest_components_are_the_nearest():
    rng = np.random.default_rng(0)
    means, x = rng.normal(size=(50, 3)), rng.normal(size=(20, 3))
    idx = nearest_components(means, x, 5)
    brute = np.argsort(((x[:, None] - means[None]) ** 2).sum(-1), 1)[:, :5]
    np.testing.assert_array_equal(np.sort(idx, 1), np.sort(brute, 1))
    assert nearest_components(means[:3], x, 16).shape == (20, 3)


def test_sparse_matches_dense_when_candidates_cover_all(frames):
    _, pts = frames
    prior = _prior(frames, k=24)
    dense, dinfo = model.update(model.start(prior), *pts[0], estep="dense")
    sparse, sinfo = model.update(model.start(prior), *pts[0], estep="sparse", n_candidates=24)
    np.testing.assert_allclose(sparse.stats.count, dense.stats.count, rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(sparse.posterior.space.mean, dense.posterior.space.mean,
                               rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(sinfo.point_loglik, dinfo.point_loglik, rtol=1e-5, atol=1e-3)


def test_sparse_close_to_dense_with_few_candidates(frames):
    """With 16 of 400 candidates the truncated responsibilities lose almost nothing."""
    _, pts = frames
    prior = _prior(frames)
    results = {}
    for estep in ("dense", "sparse"):
        state = model.start(prior)
        for xyz, rgb in pts:
            state, info = model.update(state, xyz, rgb, assign="prior", estep=estep)
        results[estep] = state, info
    d, s = results["dense"][0], results["sparse"][0]
    count_d, count_s = np.asarray(d.stats.count), np.asarray(s.stats.count)
    moved_mass = np.abs(count_s - count_d).sum() / count_d.sum()
    used = count_d > 1
    err = np.linalg.norm(np.asarray(s.posterior.space.mean - d.posterior.space.mean), axis=1)
    assert moved_mass < 0.02, moved_mass
    assert np.median(err[used]) < 1e-3
    # a truncated q(z) can only lower the per-point evidence bound
    assert np.all(np.asarray(results["sparse"][1].point_loglik)
                  <= np.asarray(results["dense"][1].point_loglik) + 1e-3)


@pytest.mark.parametrize("estep", ["dense", "sparse"])
def test_prior_mode_frames_any_order_same_posterior(frames, estep):
    _, pts = frames
    prior = _prior(frames)
    posts = []
    for order in (range(len(pts)), reversed(range(len(pts))), [3, 0, 7, 1, 6, 2, 5, 4]):
        state = model.start(prior)
        for i in order:
            state, _ = model.update(state, *pts[i], assign="prior", estep=estep)
        posts.append(state.posterior)
    for other in posts[1:]:
        for a, b in ((other.space.mean, posts[0].space.mean), (other.alpha, posts[0].alpha)):
            a, b = np.asarray(a), np.asarray(b)
            assert np.abs(a - b).max() / np.abs(b).max() < 1e-4
