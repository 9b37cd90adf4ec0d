"""Hyperparameters bound once: a state started with a config keeps it through update,
reassign and the stream stepper, and update refuses a different config."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.inference import model
from vbgs.inference.reassign import reassign
from vbgs.inference.stepper import Stepper

NOISY = model.PriorConfig(colour_noise=0.2)


def _toy(n=300, k=12, seed=0):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-1.0, 1.0, (n, 2)).astype(np.float32)
    rgb = rng.uniform(0.0, 1.0, (n, 3)).astype(np.float32)
    prior = model.init(xyz, rgb, k, key=jax.random.key(seed), scheme="data")
    return prior, xyz, rgb


def test_bound_config_is_used_without_being_passed_again():
    prior, xyz, rgb = _toy()
    bound, info = model.update(model.start(prior, NOISY), xyz, rgb)
    passed, want = model.update(model.start(prior), xyz, rgb, config=NOISY)
    default, other = model.update(model.start(prior), xyz, rgb)
    np.testing.assert_allclose(info.elbo, want.elbo, rtol=1e-6)
    np.testing.assert_allclose(bound.posterior.colour.mean, passed.posterior.colour.mean, atol=1e-6)
    assert abs(float(info.elbo) - float(other.elbo)) > 1.0  # the colour noise does matter
    assert bound.config == NOISY and passed.config is None


def test_a_different_config_is_refused_with_a_clear_message():
    prior, xyz, rgb = _toy()
    state = model.start(prior, NOISY)
    with pytest.raises(ValueError, match="differs from the one this state was started with"):
        model.update(state, xyz, rgb, config=model.PriorConfig())
    same, _ = model.update(state, xyz, rgb, config=model.PriorConfig(colour_noise=0.2))
    assert same.config == NOISY


def test_binding_survives_reassign_and_the_stepper():
    prior, xyz, rgb = _toy()
    state, info = model.update(model.start(prior, NOISY), xyz, rgb)
    moved, _ = reassign(state, xyz, rgb, info.point_loglik, key=jax.random.key(1))
    assert moved.config == NOISY
    explicit, _ = reassign(state, xyz, rgb, info.point_loglik, key=jax.random.key(1),
                           colour_noise=NOISY.colour_noise)
    np.testing.assert_array_equal(moved.prior.space.mean, explicit.prior.space.mean)
    stepped, _ = Stepper(prior, config=NOISY)(model.start(prior, NOISY), xyz, rgb)
    assert stepped.config == NOISY
    np.testing.assert_allclose(stepped.posterior.space.mean,
                               model.update(model.start(prior, NOISY), xyz, rgb)[0].posterior.space.mean,
                               atol=1e-5)


def test_features_are_the_quadratic_linear_colour_and_constant_terms():
    x = jnp.asarray([[2.0, -3.0]])
    c = jnp.asarray([[0.1, 0.2, 0.3]])
    np.testing.assert_allclose(model.features(x, c),
                               [[4.0, -6.0, -6.0, 9.0, 2.0, -3.0, 0.1, 0.2, 0.3, 1.0]], rtol=1e-6)
    np.testing.assert_allclose(model.features(x, None), [[4.0, -6.0, -6.0, 9.0, 2.0, -3.0, 1.0]])
