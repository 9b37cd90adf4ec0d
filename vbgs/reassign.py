"""Re-seed unused components where the data are poorly explained.

A component is unused when it has received less than ``min_count`` points' worth of
responsibility: its weight is still at its prior. Such components are moved (prior and
posterior alike, their statistics cleared) onto the batch points with the lowest
``log sum_k exp(l_nk)``, taking the position and colour of the point as the new
prior means. The choice among the worst points is random but fixed by ``key``.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from vbgs.model import Mixture, State, m_step

# Points' worth of responsibility below which a component counts as unused.
MIN_COUNT = 0.5


class ReassignInfo(NamedTuple):
    moved: jnp.ndarray  # [k] bool: which components were re-seeded
    n_moved: jnp.ndarray  # scalar


def _move_prior(prior: Mixture, moved, x_new, c_new) -> Mixture:
    space = prior.space._replace(mean=jnp.where(moved[:, None], x_new, prior.space.mean))
    colour = prior.colour._replace(mean=jnp.where(moved[:, None], c_new, prior.colour.mean))
    return prior._replace(space=space, colour=colour)


@partial(jax.jit, static_argnames=("pool",))
def _reassign(state: State, x, c, point_loglik, key, min_count, pool: int):
    unused = state.stats.count < min_count  # [k]
    worst = jnp.argsort(point_loglik)[:pool]  # [pool] worst-explained first
    order = jax.random.permutation(key, worst)  # random among the worst
    rank = jnp.cumsum(unused) - 1  # position of each unused component among the unused
    moved = unused & (rank < pool)
    target = order[jnp.clip(rank, 0, pool - 1)]  # [k]
    prior = _move_prior(state.prior, moved, x[target], c[target])
    def keep(a):
        return jnp.where(moved.reshape((-1,) + (1,) * (a.ndim - 1)), 0.0, a)
    stats = jax.tree_util.tree_map(keep, state.stats)
    return State(prior, m_step(prior, stats), stats), ReassignInfo(moved, moved.sum())


def reassign(
    state: State, xyz, rgb, point_loglik, *, key: jax.Array, min_count: float = MIN_COUNT
) -> tuple[State, ReassignInfo]:
    """Move unused components onto the worst-explained points of the batch
    ``xyz [n, d]``, ``rgb [n, 3]`` whose per-point log-likelihoods ``[n]`` come from the
    last E-step (``Info.point_loglik``). At most one component per point; deterministic
    under ``key``."""
    prior = state.prior
    dtype = prior.alpha.dtype
    x = jnp.asarray(xyz, dtype) - prior.origin
    c = jnp.asarray(rgb, dtype)
    n = x.shape[0]
    pool = int(min(n, prior.n_components))
    return _reassign(state, x, c, jnp.asarray(point_loglik, dtype), key, min_count, pool)
