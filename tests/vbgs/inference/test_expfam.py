"""Conjugate math against direct formulas, Monte Carlo and known identities."""

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference import expfam
from vbgs.inference.expfam import NIW, ColourNormal, Stats


def _niw(k=3, d=2, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(k, d, d))
    scale = a @ np.swapaxes(a, 1, 2) + d * np.eye(d)
    return NIW(
        jnp.asarray(rng.normal(size=(k, d)), jnp.float32),
        jnp.asarray(rng.uniform(0.5, 3, k), jnp.float32),
        jnp.asarray(rng.uniform(d + 2, d + 8, k), jnp.float32),
        jnp.asarray(scale, jnp.float32),
    )


def test_centred_quadratic_equals_direct_expected_loglik():
    q = _niw()
    x = jnp.asarray(np.random.default_rng(1).normal(size=(7, 2)), jnp.float32)
    prec = expfam.niw_expected_precision(q)
    const = expfam.niw_centred_loglik_constant(q)
    diff = x[:, None, :] - q.mean[None]  # [n, k, d]
    quad = -0.5 * jnp.einsum("nki,kij,nkj->nk", diff, prec, diff) + const[None]
    np.testing.assert_allclose(quad, expfam.niw_expected_loglik(q, x), rtol=1e-5, atol=1e-4)


def test_niw_expectations_match_monte_carlo():
    """E[Sigma^-1] and E[log|Sigma^-1|] against samples of the Wishart precision."""
    q = _niw(k=1, d=2)
    rng = np.random.default_rng(0)
    nu, psi = float(q.dof[0]), np.asarray(q.scale[0], np.float64)
    v = np.linalg.inv(psi)
    chol = np.linalg.cholesky(v)
    n = 200_000
    # Bartlett-free sampling: sum of nu outer products needs integer nu, so use
    # the Wishart as Gram matrix of Gaussian draws with nu rounded, compared with
    # the formulas at the same (integer) dof.
    nu_int = round(nu)
    g = rng.normal(size=(n, nu_int, 2)) @ chol.T
    lam = np.einsum("nti,ntj->nij", g, g)
    q_int = q._replace(dof=jnp.asarray([nu_int], jnp.float32))
    expected = np.asarray(expfam.niw_expected_precision(q_int)[0])
    np.testing.assert_allclose(lam.mean(0), expected, atol=2e-2 * np.abs(expected).max())
    np.testing.assert_allclose(
        np.linalg.slogdet(lam)[1].mean(), expfam.niw_expected_logdet_precision(q_int)[0],
        rtol=0, atol=2e-2)


def test_kl_zero_for_equal_and_positive_otherwise():
    p = _niw(seed=0)
    q = _niw(seed=1)._replace(dof=p.dof + 1.0)
    np.testing.assert_allclose(expfam.niw_kl(p, p), 0.0, atol=1e-4)
    assert np.all(np.asarray(expfam.niw_kl(q, p)) > 0)
    cp = ColourNormal(jnp.zeros((3, 3)), jnp.ones(3))
    cq = ColourNormal(jnp.full((3, 3), 0.1), jnp.full(3, 5.0))
    np.testing.assert_allclose(expfam.colour_kl(cp, cp, 0.05), 0.0, atol=1e-6)
    assert np.all(np.asarray(expfam.colour_kl(cq, cp, 0.05)) > 0)
    a = jnp.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(expfam.dirichlet_kl(a, a), 0.0, atol=1e-5)
    assert float(expfam.dirichlet_kl(a + 4.0, a)) > 0


def test_niw_kl_matches_monte_carlo_in_float64():
    with jax.enable_x64(True):
        d = 2
        p = NIW(jnp.zeros((1, d)), jnp.array([1.0]), jnp.array([5.0]), jnp.eye(d)[None] * 2.0)
        q = NIW(jnp.array([[0.3, -0.2]]), jnp.array([4.0]), jnp.array([9.0]),
                jnp.array([[[3.0, 0.5], [0.5, 2.0]]]))
        rng = np.random.default_rng(0)

        def sample(niw, n):
            v = np.linalg.inv(np.asarray(niw.scale[0]))
            g = rng.normal(size=(n, int(niw.dof[0]), d)) @ np.linalg.cholesky(v).T
            lam = np.einsum("nti,ntj->nij", g, g)
            cov = np.linalg.inv(lam)
            mu = np.asarray(niw.mean[0]) + np.einsum(
                "nij,nj->ni", np.linalg.cholesky(cov / float(niw.kappa[0])), rng.normal(size=(n, d)))
            return mu, lam

        def logpdf(niw, mu, lam):
            from scipy.stats import wishart
            v = np.linalg.inv(np.asarray(niw.scale[0]))
            lw = wishart(df=float(niw.dof[0]), scale=v).logpdf(np.moveaxis(lam, 0, -1))
            prec = lam * float(niw.kappa[0])  # mu | Lambda ~ N(m, (kappa Lambda)^-1)
            diff = mu - np.asarray(niw.mean[0])
            ln = 0.5 * (np.linalg.slogdet(prec)[1] - d * np.log(2 * np.pi)
                        - np.einsum("ni,nij,nj->n", diff, prec, diff))
            return lw + ln

        mu, lam = sample(q, 20_000)
        mc = np.mean(logpdf(q, mu, lam) - logpdf(p, mu, lam))
        np.testing.assert_allclose(float(expfam.niw_kl(q, p)[0]), mc, rtol=3e-2)


def test_posterior_equals_direct_formulas():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(50, 2)) + 5.0
    c = rng.uniform(size=(50, 3))
    r = rng.uniform(size=50)
    prior = _niw(k=1)
    st = Stats(jnp.asarray([r.sum()]), jnp.asarray([r @ x]),
               jnp.asarray([np.einsum("n,ni,nj->ij", r, x, x)]), jnp.asarray([r @ c]))
    post = expfam.niw_posterior(prior, st)
    k0, m0 = float(prior.kappa[0]), np.asarray(prior.mean[0], np.float64)
    n = r.sum()
    xbar = r @ x / n
    scatter = np.einsum("n,ni,nj->ij", r, x - xbar, x - xbar)
    psi = np.asarray(prior.scale[0]) + scatter + k0 * n / (k0 + n) * np.outer(xbar - m0, xbar - m0)
    np.testing.assert_allclose(post.mean[0], (k0 * m0 + n * xbar) / (k0 + n), rtol=1e-5)
    np.testing.assert_allclose(post.scale[0], psi, rtol=1e-4)
    np.testing.assert_allclose(post.dof[0], prior.dof[0] + n, rtol=1e-6)
    cq = expfam.colour_posterior(ColourNormal(jnp.zeros((1, 3)), jnp.ones(1)), st)
    np.testing.assert_allclose(cq.mean[0], (r @ c) / (1 + n), rtol=1e-5)
