"""reassign: unused components move onto poorly explained points, and only there."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.inference import expfam, model
from vbgs.inference.reassign import fresh_loglik, reassign

NOISE = model.PriorConfig().colour_noise
RED, BLUE = (0.9, 0.1, 0.1), (0.1, 0.1, 0.9)


def _toy(n_far: int):
    """Component 0 sits on a tight red cluster of 50 points at the origin; components
    1 and 2 sit far to the left on no data; ``n_far`` blue points lie far to the right,
    explained by nothing."""
    rng = np.random.default_rng(0)
    near = rng.normal(0.0, 0.01, (50, 2))
    far = np.array([[10.0, 0.0], [10.0, 1.0], [10.0, 2.0]])[:n_far]
    xyz = jnp.asarray(np.concatenate([near, far]), jnp.float32)
    rgb = jnp.asarray([RED] * 50 + [BLUE] * n_far, jnp.float32)
    means = jnp.asarray([[0.0, 0.0], [-10.0, 0.0], [-10.0, 5.0]], jnp.float32)
    colours = jnp.asarray([RED, RED, RED], jnp.float32)
    prior = model.make_prior(means, colours, jnp.zeros(2, jnp.float32), ell=1.0)
    state, info = model.update(model.start(prior), xyz, rgb)
    return state, info, xyz, rgb


def test_fresh_loglik_is_each_components_log_joint_at_its_own_means():
    state, *_ = _toy(2)
    q = state.posterior
    k = q.n_components
    direct = (expfam.dirichlet_expected_log(q.alpha)
              + expfam.niw_expected_loglik(q.space, q.space.mean)[jnp.arange(k), jnp.arange(k)]
              + expfam.colour_expected_loglik(q.colour, q.colour.mean, NOISE)[
                  jnp.arange(k), jnp.arange(k)])
    np.testing.assert_allclose(fresh_loglik(q, NOISE), direct, rtol=1e-5, atol=1e-4)


@pytest.mark.parametrize("n_far", [2, 3])
def test_unused_components_move_onto_the_far_points(n_far):
    state, info, xyz, rgb = _toy(n_far)
    assert np.asarray(state.stats.count[1:]).max() < 1e-3  # 1 and 2 are unused
    new, ri = reassign(state, xyz, rgb, info.point_loglik, key=jax.random.key(0),
                       colour_noise=NOISE)
    assert ri.moved.tolist() == [False, True, True]
    assert int(ri.n_moved) == 2 and int(ri.n_poor) == n_far  # the red cluster is fine
    moved_to = {tuple(np.round(np.asarray(m), 4)) for m in new.prior.space.mean[1:]}
    assert len(moved_to) == 2 and moved_to <= {tuple(p) for p in np.asarray(xyz[50:])}
    np.testing.assert_allclose(new.prior.colour.mean[1:], [BLUE, BLUE], atol=1e-6)
    # moved components start afresh: no statistics, posterior = their new prior
    assert float(jnp.abs(new.stats.count[1:]).max()) == 0.0
    np.testing.assert_allclose(new.posterior.space.mean[1:], new.prior.space.mean[1:])
    # component 0 keeps its prior, statistics and posterior
    np.testing.assert_array_equal(new.prior.space.mean[0], state.prior.space.mean[0])
    np.testing.assert_array_equal(new.stats.count[0], state.stats.count[0])
    np.testing.assert_allclose(new.posterior.space.mean[0], state.posterior.space.mean[0])


def test_one_poor_point_takes_one_component_and_none_moves_without_poor_points():
    state, info, xyz, rgb = _toy(1)
    new, ri = reassign(state, xyz, rgb, info.point_loglik, key=jax.random.key(0),
                       colour_noise=NOISE)
    assert ri.moved.tolist() == [False, True, False] and int(ri.n_poor) == 1
    np.testing.assert_allclose(new.prior.space.mean[1], [10.0, 0.0], atol=1e-6)
    np.testing.assert_array_equal(new.prior.space.mean[2], state.prior.space.mean[2])

    state, info, xyz, rgb = _toy(0)
    new, ri = reassign(state, xyz, rgb, info.point_loglik, key=jax.random.key(0),
                       colour_noise=NOISE)
    assert not bool(ri.moved.any()) and int(ri.n_poor) == 0
    np.testing.assert_array_equal(new.prior.space.mean, state.prior.space.mean)


def test_used_threshold_is_the_models_for_reassign_and_splats():
    """A count of 0.5 (model.MIN_USED_COUNT) is used: reassign leaves it and splats keep
    it; 0.49 is unused: reassign may move it and splats give it opacity 0."""
    from vbgs.render.splats import from_posterior

    assert model.used_components(np.array([0.0, 0.49, 0.5, 3.0])).tolist() == [False, False, True, True]
    state, info, xyz, rgb = _toy(1)
    counts = state.stats.count.at[1].set(0.5).at[2].set(0.49)
    state = state._replace(stats=state.stats._replace(count=counts))
    _, ri = reassign(state, xyz, rgb, info.point_loglik, key=jax.random.key(0), colour_noise=NOISE)
    assert ri.moved.tolist() == [False, False, True]

    means = jnp.asarray([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    prior = model.make_prior(means, jnp.full((4, 3), 0.5), jnp.zeros(3), ell=1.0)
    post = prior._replace(alpha=prior.alpha + jnp.asarray([0.0, 0.49, 0.5, 3.0]))
    splats = from_posterior(post, prior, drop_unused=False)
    assert (np.asarray(splats.opacities) > 0).tolist() == [False, False, True, True]
    assert from_posterior(post, prior).means.shape == (2, 3)
