"""Conjugate exponential-family pieces of the VBGS mixture, one formula per function.

Per component k (axis letters: n points, k components, d spatial dimensions):

* spatial mean and covariance ``(mu, Sigma)`` ~ Normal-Inverse-Wishart
  ``NIW(m, kappa, Psi, nu)``:  ``Sigma ~ IW(Psi, nu)``, ``mu | Sigma ~ N(m, Sigma / kappa)``;
* colour mean ``mu_c`` ~ ``N(m_c, sigma_c^2 / lambda I_3)`` with a fixed colour noise
  ``sigma_c`` (the paper's tight "delta" colour likelihood ``c ~ N(mu_c, sigma_c^2 I_3)``);
* mixing weights ``pi`` ~ ``Dirichlet(alpha)``.

All sufficient statistics are taken in the model's centred frame (see
``model.Mixture.origin``) so that coordinates far from zero lose no precision.

Reduced-precision matrix units (TF32 on NVIDIA GPUs): every product here over the
``d x d`` axes is written in centred, elementwise form (:mod:`vbgs.inference.precision`), so no
result depends on the backend's default matmul precision.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax.scipy.special import digamma, gammaln, multigammaln

from vbgs.inference.precision import quad_form

LOG_2PI = 1.8378770664093453


class NIW(NamedTuple):
    """Normal-Inverse-Wishart parameters for k components in d dimensions."""

    mean: jnp.ndarray  # [k, d]   m
    kappa: jnp.ndarray  # [k]     mean pseudo-count
    dof: jnp.ndarray  # [k]       nu > d - 1
    scale: jnp.ndarray  # [k, d, d]  Psi (positive definite)


class ColourNormal(NamedTuple):
    """Normal posterior over the colour mean: ``N(mean, sigma_c^2 / kappa I)``."""

    mean: jnp.ndarray  # [k, 3]
    kappa: jnp.ndarray  # [k]


class Stats(NamedTuple):
    """Responsibility-weighted sufficient statistics, summed over points.

    ``count = sum_n r_nk``, ``sum_x = sum_n r_nk x_n``, ``sum_xx = sum_n r_nk x_n x_n^T``
    (x in the centred frame) and ``sum_c = sum_n r_nk c_n``.

    Measured points (``x_n = y_n + e_n``, the true surface point ``y_n`` seen with a
    sensor's zero-mean noise ``e_n ~ N(0, R_n)``) also carry what their latent surface
    points differ by (:func:`vbgs.inference.model.e_step_with`): ``sum_noise = sum_n r_nk
    (x_n x_n^T - E[y_n y_n^T | x_n])`` and ``sum_shift = sum_n r_nk (x_n - E[y_n |
    x_n])``, the posteriors of ``y_n`` taken under the assigning (reference) component,
    so both stay sums over points. :func:`niw_posterior` uses them for the covariance.
    None for exact data (the default): no term, no extra work.
    """

    count: jnp.ndarray  # [k]
    sum_x: jnp.ndarray  # [k, d]
    sum_xx: jnp.ndarray  # [k, d, d]
    sum_c: jnp.ndarray  # [k, 3]
    sum_noise: jnp.ndarray | None = None  # [k, d, d] or None (exact data)
    sum_shift: jnp.ndarray | None = None  # [k, d] or None (exact data)


def zero_stats(k: int, d: int, dtype=jnp.float32, noisy: bool = False) -> Stats:
    """Statistics of no data (with zero latent moments when ``noisy``)."""
    return Stats(
        jnp.zeros((k,), dtype), jnp.zeros((k, d), dtype), jnp.zeros((k, d, d), dtype),
        jnp.zeros((k, 3), dtype), jnp.zeros((k, d, d), dtype) if noisy else None,
        jnp.zeros((k, d), dtype) if noisy else None,
    )


def add_stats(a: Stats, b: Stats) -> Stats:
    """Statistics of the union of two data sets (missing latent moments are zero)."""
    def add(x, y):
        return x if y is None else (y if x is None else x + y)

    return Stats(*(add(x, y) for x, y in zip(a, b, strict=True)))


# ----------------------------------------------------------------------------- NIW


def niw_posterior(prior: NIW, stats: Stats) -> NIW:
    """Conjugate update ``NIW(prior) x prod_n N(x_n | mu, Sigma)^{r_nk}``.

    With ``N = count``, ``S1 = sum_x``, ``S2 = sum_xx``:
    ``kappa' = kappa + N``, ``nu' = nu + N``, ``m' = (kappa m + S1) / kappa'`` and
    ``Psi' = Psi + S2 + kappa m m^T - kappa' m' m'^T``; the last is evaluated about the
    prior mean as ``Psi + (S2 - S1 m^T - m S1^T + N m m^T) - d1 d1^T / kappa'`` with
    ``d1 = S1 - N m`` to avoid cancelling large terms.

    With measurement noise (``stats.sum_noise``, ``stats.sum_shift``, see :class:`Stats`)
    the scale is that of the latent surface points ``y_n``: the same update with
    ``sum_x - sum_shift`` and ``sum_xx - sum_noise`` (a scatter of latent points, positive
    semi-definite by construction), while the mean keeps the measured ``sum_x`` (the
    noise has mean zero). Why not the latent mean too: under prior assignment the
    latent points lie on the reference component's surface, and a grown reference sits
    on one noisy point; the measured mean averages the noise away, the latent scatter
    does not depend on where the reference's surface lies along the rays. Why not the
    earlier moment deconvolution ``sum_xx - sum_n r R_n``: it is unbiased but a
    component of N points keeps a scatter error of ``sigma^2 sqrt(2 / N)`` along the
    rays; at 128 px / 20k components, 15 points each and a Kinect's 2.6 cm at 4 m, that
    is ~1.6 cm of spurious thickness and tilt on components 1.2 cm across (object,
    validation views: the exact-depth map with these covariances fell from 26.62 to
    22.80 dB; with the exact map's means 26.16, colours 26.62, opacities 26.63).
    """
    n = stats.count
    kappa = prior.kappa + n
    m0 = prior.mean
    mean = m0 + (stats.sum_x - n[:, None] * m0) / kappa[:, None]
    sum_x, sum_xx = stats.sum_x, stats.sum_xx
    if stats.sum_noise is not None:
        sum_x = sum_x - stats.sum_shift
        sum_xx = sum_xx - 0.5 * (stats.sum_noise + jnp.swapaxes(stats.sum_noise, -1, -2))
    d1 = sum_x - n[:, None] * m0  # [k, d]  sum_n r (x - m0)
    s2 = (
        sum_xx
        - sum_x[:, :, None] * m0[:, None, :]
        - m0[:, :, None] * sum_x[:, None, :]
        + n[:, None, None] * m0[:, :, None] * m0[:, None, :]
    )  # [k, d, d]  sum_n r (x - m0)(x - m0)^T
    scale = prior.scale + s2 - d1[:, :, None] * d1[:, None, :] / kappa[:, None, None]
    scale = 0.5 * (scale + jnp.swapaxes(scale, -1, -2))
    return NIW(mean, kappa, prior.dof + n, scale)


def niw_expected_precision(q: NIW) -> jnp.ndarray:
    """``E[Sigma^-1] = nu Psi^-1``, ``[k, d, d]``."""
    return q.dof[:, None, None] * jnp.linalg.inv(q.scale)


def niw_expected_logdet_precision(q: NIW, logdet_scale: jnp.ndarray | None = None
                                  ) -> jnp.ndarray:
    """``E[log |Sigma^-1|] = sum_{i=1..d} psi((nu + 1 - i) / 2) + d log 2 - log |Psi|``, ``[k]``;
    ``logdet_scale``: ``log |Psi|`` ``[k]`` when the caller has it (default ``slogdet``'s)."""
    d = q.mean.shape[-1]
    i = jnp.arange(1, d + 1, dtype=q.dof.dtype)
    psi = digamma(0.5 * (q.dof[:, None] + 1.0 - i)).sum(-1)
    if logdet_scale is None:
        logdet_scale = jnp.linalg.slogdet(q.scale)[1]
    return psi + d * jnp.log(2.0) - logdet_scale


def niw_expected_covariance(q: NIW) -> jnp.ndarray:
    """``E[Sigma] = Psi / (nu - d - 1)`` (needs ``nu > d + 1``), ``[k, d, d]``."""
    d = q.mean.shape[-1]
    return q.scale / (q.dof - d - 1.0)[:, None, None]


def niw_centred_loglik_constant(q: NIW, logdet_scale: jnp.ndarray | None = None
                                ) -> jnp.ndarray:
    """``E_q[log N(x | mu, Sigma)]`` at ``x = m``, ``[k]``: the constant of its quadratic
    about each component's own mean, ``-d/2 log 2pi + 1/2 E[log|Sigma^-1|] - d / (2
    kappa)``, so that ``E_q[log N(x | mu, Sigma)] = const - 1/2 (x - m)^T E[Sigma^-1] (x -
    m)`` (:func:`niw_expected_loglik`; :func:`vbgs.inference.model.component_terms` pairs
    it with :func:`niw_expected_precision`). It needs no precision matrix, so a caller
    that wants the constant alone pays no inverse. ``logdet_scale`` as in
    :func:`niw_expected_logdet_precision`."""
    d = q.mean.shape[-1]
    return (-0.5 * d * LOG_2PI + 0.5 * niw_expected_logdet_precision(q, logdet_scale)
            + (-0.5 * d / q.kappa))


def niw_expected_loglik(q: NIW, x: jnp.ndarray) -> jnp.ndarray:
    """``E_q[log N(x_n | mu_k, Sigma_k)]`` evaluated directly, ``[n, k]`` (reference form).

    ``= -d/2 log 2pi + 1/2 E[log|Sigma^-1|] - 1/2 (nu (x-m)^T Psi^-1 (x-m) + d / kappa)``.
    """
    d = q.mean.shape[-1]
    diff = x[:, None, :] - q.mean[None]  # [n, k, d]
    maha = quad_form(diff, niw_expected_precision(q)[None])  # [n, k]
    return (
        -0.5 * d * LOG_2PI + 0.5 * niw_expected_logdet_precision(q)[None] - 0.5 * maha
        - 0.5 * d / q.kappa[None]
    )


def niw_kl(q: NIW, p: NIW) -> jnp.ndarray:
    """``KL(q || p)`` per component, ``[k]``.

    ``= 1/2 [d kappa_p/kappa_q - d + d log(kappa_q/kappa_p)
             + kappa_p nu_q (m_q - m_p)^T Psi_q^-1 (m_q - m_p)]
        + KL(IW(Psi_q, nu_q) || IW(Psi_p, nu_p))``, the latter written on the precision
    ``Lambda ~ W(Psi^-1, nu)``:
    ``(nu_q - nu_p)/2 psi_d(nu_q/2) - nu_q d/2 + nu_q/2 tr(Psi_p Psi_q^-1)
      + nu_p/2 (log|Psi_q| - log|Psi_p|) - log Gamma_d(nu_q/2) + log Gamma_d(nu_p/2)``.
    """
    d = q.mean.shape[-1]
    psi_q_inv = jnp.linalg.inv(q.scale)
    dm = q.mean - p.mean
    mean_kl = 0.5 * (
        d * p.kappa / q.kappa - d + d * jnp.log(q.kappa / p.kappa)
        + p.kappa * q.dof * quad_form(dm, psi_q_inv)
    )
    i = jnp.arange(1, d + 1, dtype=q.dof.dtype)
    mv_digamma = digamma(0.5 * (q.dof[:, None] + 1.0 - i)).sum(-1)
    logdet_q = jnp.linalg.slogdet(q.scale)[1]
    logdet_p = jnp.linalg.slogdet(p.scale)[1]
    wishart_kl = (
        0.5 * (q.dof - p.dof) * mv_digamma
        - 0.5 * q.dof * d
        + 0.5 * q.dof * jnp.sum(p.scale * jnp.swapaxes(psi_q_inv, -1, -2), (-1, -2))
        + 0.5 * p.dof * (logdet_q - logdet_p)
        - multigammaln(0.5 * q.dof, d)
        + multigammaln(0.5 * p.dof, d)
    )
    return mean_kl + wishart_kl


def niw_log_evidence(prior: NIW, post: NIW) -> jnp.ndarray:
    """``log p(X_k)`` ``[k]``: the marginal likelihood of the points a component holds
    (Gaussian with ``(mu, Sigma) ~ NIW(prior)``; ``post`` the conjugate update on them,
    :func:`niw_posterior` on exact data), with ``n = nu_n - nu_0``:

    ``-n d/2 log pi + log Gamma_d(nu_n/2) - log Gamma_d(nu_0/2) + nu_0/2 log|Psi_0|
      - nu_n/2 log|Psi_n| + d/2 (log kappa_0 - log kappa_n)``.

    It is the ELBO ``E_q[log p(X | mu, Sigma)] - KL(q || p)`` at its optimum ``q = post``:
    the bound a component's points give, the data term and the KL in one number."""
    d = post.mean.shape[-1]
    n = post.dof - prior.dof
    return (-0.5 * n * d * jnp.log(jnp.pi)
            + multigammaln(0.5 * post.dof, d) - multigammaln(0.5 * prior.dof, d)
            + 0.5 * prior.dof * jnp.linalg.slogdet(prior.scale)[1]
            - 0.5 * post.dof * jnp.linalg.slogdet(post.scale)[1]
            + 0.5 * d * (jnp.log(prior.kappa) - jnp.log(post.kappa)))


# -------------------------------------------------------------------------- colour


def colour_posterior(prior: ColourNormal, stats: Stats) -> ColourNormal:
    """``kappa' = kappa + N``, ``m' = m + (sum_c - N m) / kappa'`` (known noise variance)."""
    kappa = prior.kappa + stats.count
    delta = stats.sum_c - stats.count[:, None] * prior.mean
    return ColourNormal(prior.mean + delta / kappa[:, None], kappa)


def colour_loglik_coefficients(q: ColourNormal, noise: float):
    """``E_q[log N(c | mu_c, s^2 I)] = -|c|^2/(2 s^2) + c^T m / s^2 + c_k`` with
    ``c_k = -3/2 log(2 pi s^2) - |m|^2 / (2 s^2) - 3 / (2 kappa)``.

    Returns ``(m / s^2 [k, 3], c_k [k])``; the ``-|c|^2 / (2 s^2)`` term is the same for
    every component and is added per point by the caller.
    """
    var = noise**2
    const = (
        -1.5 * (LOG_2PI + jnp.log(var)) - 0.5 * jnp.sum(q.mean**2, -1) / var - 1.5 / q.kappa
    )
    return q.mean / var, const


def colour_expected_loglik(q: ColourNormal, c: jnp.ndarray, noise: float) -> jnp.ndarray:
    """``E_q[log N(c_n | mu_c,k, s^2 I)] = -3/2 log(2 pi s^2) - (|c - m|^2 + 3 s^2/kappa)/(2 s^2)``,
    ``[n, k]`` (reference form)."""
    var = noise**2
    sq = jnp.sum((c[:, None, :] - q.mean[None]) ** 2, -1)
    return -1.5 * (LOG_2PI + jnp.log(var)) - 0.5 * sq / var - 1.5 / q.kappa[None]


def colour_kl(q: ColourNormal, p: ColourNormal, noise: float) -> jnp.ndarray:
    """``KL(N(m_q, s^2/kq I) || N(m_p, s^2/kp I)) =
    3/2 (kp/kq - 1 + log(kq/kp)) + kp |m_q - m_p|^2 / (2 s^2)``, ``[k]``."""
    ratio = p.kappa / q.kappa
    sq = jnp.sum((q.mean - p.mean) ** 2, -1)
    return 1.5 * (ratio - 1.0 - jnp.log(ratio)) + 0.5 * p.kappa * sq / noise**2


def colour_log_evidence(prior: ColourNormal, post: ColourNormal, noise: float) -> jnp.ndarray:
    """``log p(C_k) + sum_n |c_n|^2 / (2 s^2)`` ``[k]``: the marginal likelihood of the
    colours a component holds (``c ~ N(mu_c, s^2 I)``, ``mu_c ~ N(m_0, s^2/l_0 I)``;
    ``post`` the update on them, :func:`colour_posterior`), with ``n = l_n - l_0``:

    ``-3n/2 log(2 pi s^2) + 3/2 log(l_0 / l_n) - (l_0 |m_0|^2 - l_n |m_n|^2) / (2 s^2)``.

    The points' own ``-sum |c_n|^2 / (2 s^2)`` is left out (the statistics do not hold
    it): it is the same however the points are grouped, so differences between
    groupings (a merge) are exact."""
    var = noise**2
    n = post.kappa - prior.kappa
    return (-1.5 * n * (LOG_2PI + jnp.log(var)) + 1.5 * jnp.log(prior.kappa / post.kappa)
            - 0.5 * (prior.kappa * jnp.sum(prior.mean**2, -1)
                     - post.kappa * jnp.sum(post.mean**2, -1)) / var)


# ------------------------------------------------------------------------ Dirichlet


def dirichlet_posterior(alpha0: jnp.ndarray, stats: Stats) -> jnp.ndarray:
    """``alpha' = alpha + N``."""
    return alpha0 + stats.count


def dirichlet_expected_log(alpha: jnp.ndarray, total: jnp.ndarray | None = None) -> jnp.ndarray:
    """``E[log pi_k] = psi(alpha_k) - psi(sum alpha)``; ``total``: the sum over the whole
    Dirichlet when ``alpha`` holds only some of its components (default ``alpha.sum()``)."""
    return digamma(alpha) - digamma(alpha.sum() if total is None else total)


def dirichlet_log_evidence_terms(alpha0: jnp.ndarray, counts: jnp.ndarray) -> jnp.ndarray:
    """``log Gamma(alpha0_k + N_k) - log Gamma(alpha0_k)`` ``[k]``: component k's part of the
    mixing weights' marginal likelihood ``log B(alpha0 + N) / B(alpha0) = sum_k (this)
    + log Gamma(sum alpha0) - log Gamma(sum alpha0 + sum N)`` (the optimum over
    ``q(pi)`` of ``sum_k N_k E[log pi_k] - KL(q(pi) || Dir(alpha0))``)."""
    return gammaln(alpha0 + counts) - gammaln(alpha0)


def dirichlet_kl(q: jnp.ndarray, p: jnp.ndarray) -> jnp.ndarray:
    """``KL(Dir(q) || Dir(p)) = lnG(sum q) - sum lnG(q) - lnG(sum p) + sum lnG(p)
    + sum (q - p)(psi(q) - psi(sum q))`` (a scalar)."""
    return (
        gammaln(q.sum()) - gammaln(q).sum() - gammaln(p.sum()) + gammaln(p).sum()
        + jnp.sum((q - p) * dirichlet_expected_log(q))
    )
