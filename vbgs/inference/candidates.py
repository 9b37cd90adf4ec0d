"""Sparse E-step: each point scores only the few components nearest to it.

The dense E-step costs ``n x k``. Here a KD-tree over the component means (rebuilt on
every call, so it follows means that move) gives each point its ``C`` spatially
nearest components, and responsibilities are computed over those alone: a truncated
variational posterior ``q(z_n)`` supported on the candidates. The ELBO stays a valid
lower bound, and cost grows with ``n x C``.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np



# Candidates per point by default: enough that the truncated responsibilities match
# the dense ones to within rendering precision for splat-sized components.
# Fewer draw better with exact depth (validation views, fit-scene's defaults,
# `python -m experiments.studies.val_probe fit-scene --scene S --candidates C`), object / room /
# walk at C = 4, 8, 12, 16: 26.72 / 23.07 / 21.52, 26.74 / 22.86 / 21.68, 26.60 / 22.77 /
# 21.67, 26.58 / 22.67 / 21.59 dB (means 23.77, 23.76, 23.68, 23.61), seconds a frame
# 10-20% fewer at 8; the 640x480 room at N = 80000 (2 validation views) 23.10 / 23.06 /
# 23.04 at 8 / 12 / 16. Under a measured sensor fewer lose: the object under the Kinect
# (`--simulate-sensor kinect --sensor kinect`) 24.35 at 8 against 24.61 at 16, its noise
# (2.6 cm) wider than a component. So 16 under a measured sensor and 8 with exact depth.
DEFAULT_CANDIDATES = 16
# With exact depth 8 (the validation views above; :func:`default_candidates`).
EXACT_CANDIDATES = 8


def default_candidates(exact: bool) -> int:
    """Candidates per point when none are asked: :data:`EXACT_CANDIDATES` for exact depth,
    :data:`DEFAULT_CANDIDATES` under a measured sensor (whose noise is wider than a
    component, so that a point's latent surface point may lie under a farther one)."""
    return EXACT_CANDIDATES if exact else DEFAULT_CANDIDATES


def nearest_components(means, x, n_candidates: int = DEFAULT_CANDIDATES) -> np.ndarray:
    """Indices ``[n, C]`` of the ``C`` component means ``[k, d]`` nearest to each point
    ``x [n, d]`` (Euclidean, host KD-tree), ``C = min(n_candidates, k)``."""
    return query(means_tree(means), x, n_candidates)


class MeansTree:
    """A KD-tree over component means ``[k, d]`` (build once while the means are fixed),
    queried as scipy's ``cKDTree`` is (``n``; ``query(x, k)`` -> distances and int64
    indices, ``[m]`` for ``k = 1``, else ``[m, k]``).

    pykdtree's tree (float64, queries in OpenMP threads): the same nearest means as
    scipy's, in less time on the queries a frame makes (16 candidates for 16k points
    over 20k means: 40 against 61 ms on 2 cores, the build 2.8 against 4.0 ms; 8
    candidates 17.5 ms). Means exactly as far from a point are listed in an order of
    the tree's own, not scipy's: the same sets, which the E-step sums in another order."""

    def __init__(self, means):
        from pykdtree.kdtree import KDTree  # imported when used

        self.data = np.ascontiguousarray(means, np.float64)
        self.n = len(self.data)
        self._tree = KDTree(self.data)

    def query(self, x, k: int = 1, workers=None) -> tuple[np.ndarray, np.ndarray]:
        """The ``k <= n`` nearest means of each point of ``x [m, d]``; ``workers`` is
        scipy's (the threads are OpenMP's here)."""
        if not 1 <= k <= self.n:
            raise ValueError(f"k must lie in [1, {self.n}] (the tree's means), got {k}")
        dist, idx = self._tree.query(np.ascontiguousarray(x, np.float64), k=k)
        return dist, idx.astype(np.int64)


def means_tree(means) -> MeansTree:
    """A :class:`MeansTree` over component means ``[k, d]``."""
    return MeansTree(means)


def query(tree: MeansTree, x, n_candidates: int = DEFAULT_CANDIDATES) -> np.ndarray:
    """:func:`nearest_components` against a prebuilt :func:`means_tree`."""
    return query_with_distance(tree, x, n_candidates)[1]


def query_with_distance(tree: MeansTree, x, n_candidates: int = DEFAULT_CANDIDATES
                        ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`query` and each point's distance to its nearest mean: ``([n], [n, C])``."""
    c = int(min(n_candidates, tree.n))
    if c < 1:
        raise ValueError(f"n_candidates must be at least 1, got {n_candidates}")
    dist, idx = tree.query(np.asarray(x, np.float64), k=c, workers=-1)
    return (np.asarray(dist).reshape(len(x), c)[:, 0],
            np.asarray(idx, np.int32).reshape(len(x), c))


def candidate_logits(x: jnp.ndarray, c: jnp.ndarray, terms, cand: jnp.ndarray,
                     colour_noise: float, ray: jnp.ndarray | None = None) -> jnp.ndarray:
    """``l_nc``: log-joint of each point with its candidates, ``[n, C]``, in centred form
    ``const_k - 1/2 (x_n - m_k)^T P_k (x_n - m_k) - |c_n - mc_k|^2 / (2 sigma_c^2)``
    with ``k = cand_nc`` (see :class:`vbgs.inference.model.Terms`); ``x [n, d]``, ``c [n, 3]``.

    Elementwise products of centred quantities only: exact whatever the backend's
    matmul precision (TF32 included), and no large terms cancel. The terms are packed
    into one ``[rows, k]`` table and gathered once, one contiguous ``[n, C]`` plane per
    row, and the quadratic form is unrolled over the ``d (d + 1) / 2`` distinct entries
    of the symmetric ``P_k`` (fast on CPUs, where small trailing axes vectorise badly).

    ``ray [n, d]``: each point's measurement noise along its ray, ``R_n = u_n u_n^T``
    (a depth sensor's error moves a point along the ray it was seen on). The point is
    then scored under the component convolved with its noise, ``N(x | m_k, Sigma_k +
    R_n)`` with ``P_k`` for ``Sigma_k^-1``: by Sherman-Morrison, with ``q = u^T P_k u``
    and ``a = u^T P_k (x - m_k)``, the Mahalanobis term loses ``a^2 / (1 + q)`` and the
    log-determinant gains ``log(1 + q)``.
    """
    return _logits(x, c, terms, cand, colour_noise, ray)[0]


def candidate_latent(x: jnp.ndarray, c: jnp.ndarray, terms, cand: jnp.ndarray,
                     colour_noise: float, ray: jnp.ndarray):
    """:func:`candidate_logits` with noise, and the latent surface point of each point
    under each candidate: ``(logits, beta, gamma)``, each ``[n, C]``.

    A point measured as ``x = y + e u`` (``e ~ N(0, 1)``, ``u`` its noise along the
    ray) from a surface point ``y ~ N(m_k, Sigma_k)`` has, given ``x``, the Gaussian
    posterior ``E[y | x] = x - beta u`` and ``Cov[y | x] = gamma u u^T`` with
    ``beta = a / (1 + q)``, ``gamma = 1 / (1 + q)`` (``a``, ``q`` as in
    :func:`candidate_logits`; Sherman-Morrison on ``R (Sigma + R)^-1``): the point
    slides along its ray onto the component's surface, and keeps as much of its noise
    as the component's own spread along the ray allows."""
    logits, a, q = _logits(x, c, terms, cand, colour_noise, ray)
    return (logits,) + latent_shift(a, q)


def latent_shift(a: jnp.ndarray, q: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """``(beta, gamma)`` of :func:`candidate_latent` from :func:`scores`' ``a`` and
    ``q``: ``gamma = 1 / (1 + q)``, ``beta = a gamma``."""
    gamma = 1.0 / (1.0 + q)
    return a * gamma, gamma


def latent_moments(beta: jnp.ndarray, gamma: jnp.ndarray, x: jnp.ndarray, ray: jnp.ndarray
                   ) -> list[tuple[jnp.ndarray, jnp.ndarray]]:
    """What a point's latent surface point under a candidate adds to the statistics
    beyond the measured point (:func:`vbgs.inference.model.e_step_with`), as pairs of a
    weight per point and candidate (``beta``, ``gamma`` ``[..., C]``) and a feature per
    point (``x``, ``ray`` ``[..., d]``): the moments are ``sum r w f``. The
    ``d * d`` columns are ``beta (x u^T + u x^T) - (beta^2 + gamma) u u^T``, the ``d``
    after them ``beta u`` (``x x^T - E[y y^T | x]`` and ``x - E[y | x]``). The E-steps
    sum each pair in the arrangement their layout favours."""
    d = x.shape[-1]
    xu = x[..., :, None] * ray[..., None, :]
    sym = (xu + jnp.swapaxes(xu, -1, -2)).reshape(x.shape[:-1] + (d * d,))
    uu = (ray[..., :, None] * ray[..., None, :]).reshape(x.shape[:-1] + (d * d,))
    return [(beta, sym), (-(beta * beta + gamma), uu), (beta, ray)]


def _logits(x, c, terms, cand, colour_noise, ray):
    """The logits ``[n, C]`` and, with ``ray``, ``a`` and ``q`` ``[n, C]`` (else None)."""
    return scores(x, c, gathered(terms, cand), colour_noise, ray)


def gathered(terms, cand: jnp.ndarray) -> list[jnp.ndarray]:
    """The terms of the candidates ``cand [..., C]``: one array shaped as ``cand`` per
    row of ``mean [d], prec [d * d], colour_mean [3], const`` (the order
    :func:`scores` reads).

    One gather per row, each a contiguous plane: gathered as one ``[rows, n, C]``
    block, XLA:CPU lays it out row-minor and every use in the fused arithmetic reads it
    strided (4x slower with a ray: 0.49 against 0.12 s at 262k points x 16)."""
    d = terms.mean.shape[1]
    k = terms.mean.shape[0]
    table = jnp.concatenate([terms.mean.T, terms.prec.reshape(k, d * d).T,
                             terms.colour_mean.T, terms.const[None]], 0)  # [d + d*d + 4, k]
    return [row[cand] for row in table]


def scores(x, c, g, colour_noise, ray=None):
    """:func:`_logits` from the candidates' :func:`gathered` terms ``g``: points ``x [...,
    d]``, ``c [..., 3]``, ``ray [..., d]`` and terms that broadcast against them with a
    trailing candidate axis (``[n, C]`` for points ``[n, d]``; ``[T, 1, C]`` for a
    frame's tiles of points ``[T, P, d]`` that share their candidates)."""
    d = x.shape[-1]
    diff = [x[..., i, None] - g[i] for i in range(d)]  # d x [..., C]
    maha = 0.0
    for i in range(d):
        for j in range(i, d):
            p_ij = g[d + i * d + j]
            maha = maha + (1.0 if i == j else 2.0) * p_ij * diff[i] * diff[j]
    base = d + d * d
    colour = sum((c[..., i, None] - g[base + i]) ** 2 for i in range(3))
    logits = g[base + 3] - 0.5 * maha - 0.5 * colour / colour_noise**2
    if ray is None:
        return logits, None, None
    u = [ray[..., i, None] for i in range(d)]  # d x [..., 1]
    pu = [sum(g[d + i * d + j] * u[j] for j in range(d)) for i in range(d)]  # P_k u
    q = sum(u[i] * pu[i] for i in range(d))  # [..., C]
    a = sum(pu[i] * diff[i] for i in range(d))
    return logits + 0.5 * a**2 / (1.0 + q) - 0.5 * jnp.log1p(q), a, q


def scatter_pair_moments(acc: jnp.ndarray, resp: jnp.ndarray, psi: jnp.ndarray,
                         cand: jnp.ndarray) -> jnp.ndarray:
    """``acc[k] += sum_{n, c: cand_nc = k} r_nc psi_nc``; ``psi [n, C, G]`` a feature of
    each point and candidate (the latent moments of :func:`candidate_latent`)."""
    contrib = resp[:, :, None] * psi  # [n, C, G]
    return acc.at[cand.reshape(-1)].add(contrib.reshape(-1, psi.shape[-1]))


def scatter_moments(acc: jnp.ndarray, resp: jnp.ndarray, phi: jnp.ndarray,
                    cand: jnp.ndarray) -> jnp.ndarray:
    """``acc[k] += sum_{n, c: cand_nc = k} r_nc phi_n``; acc ``[k, F]``, resp ``[n, C]``:
    :func:`scatter_pair_moments` with one feature per point, whatever its candidate."""
    return scatter_pair_moments(acc, resp, phi[:, None, :], cand)
