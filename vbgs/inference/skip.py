"""Skip what the model already explains: points (and frames) a stream need not learn.

A point ``(x_n, c_n)`` is **well explained** when its nearest used component k*
(nearest posterior mean; used: at least ``min_count`` points' worth of data) gives it
a log-joint within ``margin`` nats of the best that component gives any point, its
own peak ``l_k*k*`` (:func:`vbgs.inference.reassign.fresh_loglik`):

    l_nk* >= l_k*k* - margin,   l_nk = E_q[log pi_k + log N(x_n | mu_k, Sigma_k)
                                          + log N(c_n | mu_c,k, sigma_c^2 I)]

(the E-step's log-joint, :func:`vbgs.inference.model.log_joint_weights`). ``margin`` is unit-free:
half the squared Mahalanobis distance plus half the squared colour error in units of
``sigma_c``, so ``margin = 2`` keeps points more than about two standard deviations
away in space and colour together. Scoring one component per point costs a KD-tree
query and one dot product per point, a small part of the sparse E-step it saves.
Skipping drops data, so the posterior is no longer the one of the whole stream: a
trade of seconds against fidelity, measured in the README.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.model import Mixture, bucket_size, features, log_joint_weights
from vbgs.inference.reassign import fresh_loglik

MIN_COUNT = 2.0  # points' worth of data a component needs before it can explain a point


@jax.jit
def _scores(q: Mixture, x, c, nearest, colour_noise):
    weights = log_joint_weights(q, colour_noise)  # [k, F]
    own = jnp.sum(features(x, c) * weights[nearest], -1) - 0.5 * jnp.sum(c**2, -1) / colour_noise**2
    return own, fresh_loglik(q, colour_noise)[nearest]


def well_explained(q: Mixture, counts, xyz, rgb, *, margin: float, colour_noise: float,
                   min_count: float = MIN_COUNT) -> np.ndarray:
    """``[n]`` bool: points of ``xyz [n, d]``, ``rgb [n, 3]`` (world units) that the
    posterior ``q`` with per-component data ``counts [k]`` already explains (module
    docstring)."""
    if not margin >= 0:
        raise ValueError(f"the skip margin must be a non-negative number of nats, got {margin!r}")
    used = np.flatnonzero(np.asarray(counts) >= min_count)
    if used.size == 0:
        return np.zeros(len(xyz), bool)
    dtype = q.alpha.dtype
    n = len(xyz)
    x = np.asarray(xyz, np.float64) - np.asarray(q.origin, np.float64)
    means = np.asarray(q.space.mean, np.float64)[used]
    from scipy.spatial import cKDTree  # imported when used: 0.2-0.4 s at start-up

    _, idx = cKDTree(means).query(x, k=1, workers=-1)
    pad = bucket_size(n) - n  # a few compiled sizes, not one per frame
    nearest = jnp.asarray(np.pad(used[idx], (0, pad)), jnp.int32)
    x = jnp.asarray(np.pad(x, ((0, pad), (0, 0))), dtype)
    c = jnp.asarray(np.pad(np.asarray(rgb), ((0, pad), (0, 0))), dtype)
    own, peak = _scores(q, x, c, nearest, jnp.asarray(colour_noise, dtype))
    return np.asarray(own >= peak - margin)[:n]
