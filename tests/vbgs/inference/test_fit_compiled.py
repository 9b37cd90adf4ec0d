"""The compiled batch fit (one while_loop) equals the per-iteration host loop, its
reference: posterior, ELBO trace, iteration count, convergence and re-seeded count."""

import jax
import numpy as np
import pytest

from vbgs.data.images import image_to_points, load_image
from vbgs.inference import model
from vbgs.inference.fit import fit, fit_steps


@pytest.fixture(scope="module")
def points():
    uv, rgb = image_to_points(load_image("astronaut", 24))
    return uv[:451], rgb[:451]  # 451 points: padded to 480 inside, re-seeding sees 451


def _same(a, b, assert_same):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        assert_same(x, y)


@pytest.mark.xla_default  # equal to the bit at XLA's default (tests/conftest.py)
def test_compiled_fit_with_reseeding_equals_host_loop(points, assert_same):
    uv, rgb = points
    prior = model.init(uv, rgb, 60, key=jax.random.key(2), scheme="random")
    post, info = fit(prior, uv, rgb, iters=5, tol=0.0, key=jax.random.key(5))
    ref, ref_info = fit_steps(prior, uv, rgb, iters=5, tol=0.0, key=jax.random.key(5))
    _same(post, ref, assert_same)
    assert_same(info.elbo, ref_info.elbo)
    assert info.iterations == ref_info.iterations == 5
    assert info.moved == ref_info.moved > 0  # a random start leaves components to re-seed


@pytest.mark.xla_default  # equal to the bit at XLA's default (tests/conftest.py)
def test_compiled_fit_stops_where_the_host_loop_does(points, assert_same):
    uv, rgb = points
    prior = model.init(uv, rgb, 30, key=jax.random.key(0), scheme="data")
    post, info = fit(prior, uv, rgb, iters=40, tol=1e-3)
    ref, ref_info = fit_steps(prior, uv, rgb, iters=40, tol=1e-3)
    assert info.converged and ref_info.converged
    assert info.iterations == ref_info.iterations < 40
    assert_same(info.elbo, ref_info.elbo)
    _same(post, ref, assert_same)


def test_compiled_fit_refuses_points_of_the_wrong_dimension(points):
    uv, rgb = points
    prior = model.init(uv, rgb, 10, key=jax.random.key(0))
    xyz = np.concatenate([uv, np.zeros((len(uv), 1), uv.dtype)], 1)
    with pytest.raises(ValueError, match="3-D but the model is 2-D"):
        fit(prior, xyz, rgb)
