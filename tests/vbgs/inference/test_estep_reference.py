"""The E-step against a naive per-point, per-component loop over the model's formulas.

``l_nk = E[log pi_k] + E[log N(x_n | mu_k, Sigma_k)] + E[log N(c_n | mu_c,k, s^2 I)]``
written out term by term in float64 numpy (digamma from scipy), then
``r_nk = exp(l_nk - log sum_j exp(l_nj))`` and the weighted statistics. The fast E-step
folds all three terms into one matrix product (``model.log_joint_weights``); this holds
it to the formulas, the colour and weight terms included.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import digamma, logsumexp

from vbgs.inference import expfam, model

NOISE = 0.05
LOG_2PI = np.log(2 * np.pi)


def _naive_log_joint(q: model.Mixture, x, c, noise=NOISE) -> np.ndarray:
    """``l [n, k]`` by a plain loop over points and components."""
    alpha = np.asarray(q.alpha, np.float64)
    m, kappa = np.asarray(q.space.mean, np.float64), np.asarray(q.space.kappa, np.float64)
    nu, psi = np.asarray(q.space.dof, np.float64), np.asarray(q.space.scale, np.float64)
    mc, kc = np.asarray(q.colour.mean, np.float64), np.asarray(q.colour.kappa, np.float64)
    x, c = np.asarray(x, np.float64), np.asarray(c, np.float64)
    n, d = x.shape
    k = alpha.shape[0]
    var = noise**2
    out = np.empty((n, k))
    for i in range(n):
        for j in range(k):
            log_pi = digamma(alpha[j]) - digamma(alpha.sum())  # Dirichlet
            precision = nu[j] * np.linalg.inv(psi[j])  # E[Sigma^-1]
            logdet = (sum(digamma((nu[j] + 1 - t) / 2) for t in range(1, d + 1))
                      + d * np.log(2) - np.linalg.slogdet(psi[j])[1])  # E[log|Sigma^-1|]
            diff = x[i] - m[j]
            space = (-0.5 * d * LOG_2PI + 0.5 * logdet - 0.5 * diff @ precision @ diff
                     - 0.5 * d / kappa[j])
            colour = (-1.5 * (LOG_2PI + np.log(var))
                      - (np.sum((c[i] - mc[j]) ** 2) + 3 * var / kc[j]) / (2 * var))
            out[i, j] = log_pi + space + colour
    return out


def _naive_stats(logits, x, c, w):
    lse = logsumexp(logits, axis=1)
    r = np.exp(logits - lse[:, None]) * np.asarray(w, np.float64)[:, None]  # [n, k]
    x, c = np.asarray(x, np.float64), np.asarray(c, np.float64)
    return (r.sum(0), r.T @ x, np.einsum("nk,ni,nj->kij", r, x, x), r.T @ c), lse


def _case(d, k=6, n=32, seed=0):
    """A posterior (random soft assignments of 200 points) with unequal counts, kappas,
    dofs and colours, and a batch of points (centred frame) with the last 5 marked as
    padding (weight 0)."""
    rng = np.random.default_rng(seed)
    xyz = jnp.asarray(rng.normal(size=(200, d)), jnp.float32)
    rgb = jnp.asarray(rng.uniform(size=(200, 3)), jnp.float32)
    prior = model.init(xyz, rgb, k, key=jax.random.key(seed), scheme="data",
                       config=model.PriorConfig(colour_noise=NOISE))
    r = jnp.asarray(rng.dirichlet(np.linspace(0.1, 3.0, k), 200), jnp.float32)  # [200, k]
    x0 = xyz - prior.origin
    q = model.m_step(prior, expfam.Stats(r.sum(0), r.T @ x0,
                                         jnp.einsum("nk,ni,nj->kij", r, x0, x0), r.T @ rgb))
    x = jnp.asarray(rng.normal(size=(n, d)), jnp.float32) - q.origin
    c = jnp.asarray(rng.uniform(size=(n, 3)), jnp.float32)
    w = jnp.asarray(np.r_[np.ones(n - 5), np.zeros(5)], jnp.float32)
    return q, x, c, w


def _close(stats, lse, ref_stats, ref_lse):
    np.testing.assert_allclose(lse, ref_lse, rtol=1e-5, atol=1e-3)
    assert stats.sum_noise is None  # exact data: no noise moments
    for got, want in zip(stats[:4], ref_stats, strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4 * np.abs(want).max())


@pytest.mark.parametrize("d", [2, 3])
def test_reference_forms_are_the_naive_log_joint(d):
    q, x, c, _ = _case(d)
    ref = _naive_log_joint(q, x, c)
    forms = (expfam.dirichlet_expected_log(q.alpha)[None]
             + expfam.niw_expected_loglik(q.space, x)
             + expfam.colour_expected_loglik(q.colour, c, NOISE))
    np.testing.assert_allclose(forms, ref, rtol=1e-5, atol=1e-3)
    # sanity: the weight and colour terms matter here (not constant over components)
    assert np.ptp(np.asarray(expfam.dirichlet_expected_log(q.alpha))) > 0.5
    assert np.ptp(np.asarray(expfam.colour_expected_loglik(q.colour, c, NOISE))) > 10


@pytest.mark.parametrize("d", [2, 3])
def test_dense_e_step_equals_naive_loop(d):
    q, x, c, w = _case(d)
    ref_stats, ref_lse = _naive_stats(_naive_log_joint(q, x, c), x, c, w)
    stats, lse = model.e_step(q, x, c, w, NOISE, 8)
    _close(stats, lse, ref_stats, ref_lse)


def test_sparse_e_step_equals_naive_loop_over_each_points_candidates():
    q, x, c, w = _case(3, k=6)
    logits = _naive_log_joint(q, x, c)
    rng = np.random.default_rng(1)
    cand = np.stack([rng.permutation(6)[:3] for _ in range(x.shape[0])])  # [n, 3]
    masked = np.full_like(logits, -np.inf)
    np.put_along_axis(masked, cand, np.take_along_axis(logits, cand, 1), 1)
    ref_stats, ref_lse = _naive_stats(masked, x, c, w)
    stats, lse = model.e_step(q, x, c, w, NOISE, 8, jnp.asarray(cand))
    _close(stats, lse, ref_stats, ref_lse)
