"""Re-seed unused components where the data are poorly explained.

A component is unused when it has received less than ``min_count`` points' worth of
responsibility: its weight is still at its prior. A point is poorly explained when
its log-likelihood under the model, ``log sum_k exp(l_nk)``, is below what a fresh
component placed exactly on it would give it (the log-joint of an unused component
at its own prior means). Unused components are moved onto such points (prior and
posterior alike, their statistics cleared), taking the point's position and colour
as their new prior means: a move only where it helps, so streams do not pull
components away from regions they have not reached yet. Which poorly explained
points receive a component is random, fixed by ``key``.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from vbgs.inference.model import (
    MIN_USED_COUNT,
    Mixture,
    State,
    bound_config,
    features,
    log_joint_weights,
    m_step,
    used_components,
)

MIN_COUNT = MIN_USED_COUNT  # the model's "used" threshold, under the name callers already import


class ReassignInfo(NamedTuple):
    moved: jnp.ndarray  # [k] bool: which components were re-seeded
    n_moved: jnp.ndarray  # scalar
    n_poor: jnp.ndarray  # scalar: points explained worse than a fresh component would


def fresh_loglik(q: Mixture, colour_noise: float) -> jnp.ndarray:
    """``l_kk``: each component's log-joint at its own spatial and colour means, ``[k]``."""
    phi = features(q.space.mean, q.colour.mean)  # [k, F]
    own = jnp.sum(phi * log_joint_weights(q, colour_noise), -1)
    return own - 0.5 * jnp.sum(q.colour.mean**2, -1) / colour_noise**2


def _move_prior(prior: Mixture, moved, x_new, c_new) -> Mixture:
    space = prior.space._replace(mean=jnp.where(moved[:, None], x_new, prior.space.mean))
    colour = prior.colour._replace(mean=jnp.where(moved[:, None], c_new, prior.colour.mean))
    return prior._replace(space=space, colour=colour)


@partial(jax.jit, static_argnames=("colour_noise",))
def reassign_centred(state: State, x, c, point_loglik, key, min_count,
                     colour_noise: float) -> tuple[State, ReassignInfo]:
    """:func:`reassign` on centred positions ``x [n, d]`` (``xyz - origin``), colours
    ``c [n, 3]`` and log-likelihoods ``[n]``, all on the device (compiled; callable
    inside a compiled loop such as :func:`vbgs.inference.fit.fit`'s)."""
    pool = int(min(x.shape[0], state.prior.n_components))
    unused = ~used_components(state.stats.count, min_count)  # [k]
    fresh = jnp.max(jnp.where(unused, fresh_loglik(state.posterior, colour_noise), -jnp.inf))
    poor = point_loglik < fresh  # [n]
    priority = jnp.where(poor, jax.random.uniform(key, poor.shape), 2.0)
    targets = jnp.argsort(priority)[:pool]  # poorly explained points in random order
    rank = jnp.cumsum(unused) - 1  # position of each unused component among the unused
    moved = unused & (rank < jnp.minimum(poor.sum(), pool))
    target = targets[jnp.clip(rank, 0, pool - 1)]  # [k]
    prior = _move_prior(state.prior, moved, x[target], c[target])

    def clear(a):
        return jnp.where(moved.reshape((-1,) + (1,) * (a.ndim - 1)), 0.0, a)

    stats = jax.tree_util.tree_map(clear, state.stats)
    return state._replace(prior=prior, posterior=m_step(prior, stats), stats=stats), ReassignInfo(moved, moved.sum(), poor.sum())


def reassign(
    state: State,
    xyz,
    rgb,
    point_loglik,
    *,
    key: jax.Array,
    colour_noise: float | None = None,
    min_count: float = MIN_COUNT,
) -> tuple[State, ReassignInfo]:
    """Move unused components onto poorly explained points of the batch
    ``xyz [n, d]``, ``rgb [n, 3]``, given each point's log-likelihood ``[n]`` under the
    model (``Info.point_loglik`` of an update). At most one component per point;
    deterministic under ``key``. ``colour_noise``: the state's bound config's when left
    out (:func:`vbgs.inference.model.bound_config`)."""
    if colour_noise is None:
        colour_noise = bound_config(state).colour_noise
    prior = state.prior
    dtype = prior.alpha.dtype
    x = jnp.asarray(xyz, dtype) - prior.origin
    c = jnp.asarray(rgb, dtype)
    return reassign_centred(state, x, c, jnp.asarray(point_loglik, dtype), key, min_count,
                            float(colour_noise))
