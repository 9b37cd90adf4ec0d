"""vbgs.inference.merge under components="auto": merges taken when they raise the bound."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.inference import expfam, merge, model
from vbgs.inference.model import PriorConfig

CONFIG = PriorConfig()


def halves_state(gap: float, seed: int = 0):
    """Two components, each holding one half (split at x = gap / 2) of 400 points of one
    flat Gaussian (sd 1, 1, 0.01) of one colour, the second half shifted by ``gap``."""
    rng = np.random.default_rng(seed)
    x = rng.multivariate_normal(np.zeros(3), np.diag([1.0, 1.0, 1e-4]), 400)
    label = (x[:, 0] > 0).astype(int)
    x[label == 1, 0] += gap
    c = 0.5 + 0.01 * rng.normal(size=(400, 3))
    means = np.stack([x[label == k].mean(0) for k in (0, 1)]).astype(np.float32)
    prior = model.make_prior(jnp.asarray(means), jnp.full((2, 3), 0.5), jnp.zeros(3), 1.0,
                             CONFIG)
    r = np.eye(2, dtype=np.float32)[label]
    x = x.astype(np.float32)
    stats = expfam.Stats(jnp.asarray(r.sum(0)), jnp.asarray(r.T @ x),
                         jnp.asarray(np.einsum("nk,ni,nj->kij", r, x, x)),
                         jnp.asarray((r.T @ c).astype(np.float32)))
    return model.State(prior, model.m_step(prior, stats), stats)


def test_two_halves_of_one_gaussian_merge_two_apart_do_not():
    one, apart = halves_state(0.0), halves_state(6.0)
    pair, both = np.array([[0, 1]]), np.ones(2, bool)
    gain_one = merge.merge_gains(one, pair, CONFIG.colour_noise)[0]
    gain_apart = merge.merge_gains(apart, pair, CONFIG.colour_noise)[0]
    # measured +223.3 and -324.2 nats (400 points, seed 0)
    assert 180 < gain_one < 270 and -400 < gain_apart < -250
    np.testing.assert_array_equal(merge.bound_pairs(one, both, CONFIG.colour_noise), pair)
    assert len(merge.bound_pairs(apart, both, CONFIG.colour_noise)) == 0


def test_log_evidence_is_the_bound_at_its_optimum():
    """E_k = E_q[log p(X | theta)] - KL(q || p) at q = the posterior: the evidence
    formulas agree with the model's own expected log-likelihood and KL."""
    rng = np.random.default_rng(1)
    x = rng.multivariate_normal(np.zeros(3), np.diag([1.0, 1.0, 1e-4]), 50).astype(np.float32)
    prior = model.make_prior(jnp.zeros((1, 3)), jnp.full((1, 3), 0.5), jnp.zeros(3), 1.0,
                             CONFIG)
    stats = expfam.Stats(jnp.asarray([50.0]), jnp.asarray(x.sum(0, keepdims=True)),
                         jnp.asarray((x.T @ x)[None]), jnp.zeros((1, 3)))
    @jax.jit  # one compilation, not one per eager op
    def terms(prior, stats, x):
        post = model.m_step(prior, stats)
        return (expfam.niw_expected_loglik(post.space, x).sum(),
                expfam.niw_kl(post.space, prior.space)[0],
                expfam.niw_log_evidence(prior.space, post.space)[0])

    ell, kl, evidence = map(float, terms(prior, stats, jnp.asarray(x)))
    assert evidence == pytest.approx(ell - kl, abs=0.05)
