"""Capacity that grows in buckets: more slots for a mixture without a compilation per frame.

A model of fixed capacity keeps its arrays at ``[K, ...]`` so the compiled update is
compiled once (:mod:`vbgs.inference.stepper`). When the number of components is chosen
from the data (``components="auto"``, :mod:`vbgs.mapping.mapper`) the map needs more
slots as it meets new ground; growing the arrays to the exact count each frame would
compile the update for every new shape. Here the capacity only takes the sizes
``first x 2^j`` (:func:`bucket`), at most a ceiling, so a stream compiles its update once
per bucket (a handful per stream: 4096 to 131072 is six). New slots are empty
(:func:`vbgs.inference.grow.empty_prior`: no responsibility, far from the data), their
statistics zero, so widening changes no posterior and no assignment.
"""

from __future__ import annotations

import jax
import numpy as np

from vbgs.inference.grow import _m_step, empty_prior
from vbgs.inference.model import PriorConfig, State


def bucket(n: int, first: int, ceiling: int) -> int:
    """The smallest ``first x 2^j`` that holds ``n`` slots, at most ``ceiling``."""
    size = max(int(first), 1)
    while size < n:
        size *= 2
    return int(min(size, ceiling))


def widen_rows(sums, k: int):
    """Per-component sums (a NamedTuple of ``[k0, ...]`` arrays or None, e.g.
    :class:`vbgs.inference.expfam.Stats`, opacity evidence) with zero rows up to ``k``."""

    def one(x):
        if x is None:
            return None
        x = np.asarray(x)
        pad = np.zeros((k - x.shape[0],) + x.shape[1:], x.dtype)
        return jax.device_put(np.concatenate([x, pad]))

    return type(sums)(*(one(x) for x in sums))


def widen(state: State, k: int, cell: float, config: PriorConfig) -> State:
    """``state`` with ``k`` slots (at least its own): the new ones empty rows of a prior at
    cell length ``cell`` (the rows :func:`vbgs.inference.grow.empty_prior` gives a model of
    ``k`` slots, so every empty slot keeps its place), their statistics zero."""
    prior = state.prior
    k0 = prior.n_components
    if k <= k0:
        return state
    empty = empty_prior(k, prior.origin, cell, config, prior.alpha.dtype)

    def join(old, new):
        return jax.device_put(np.concatenate([np.asarray(old), np.asarray(new)[k0:]]))

    wide = jax.tree.map(join, prior._replace(origin=None), empty._replace(origin=None))
    wide = wide._replace(origin=prior.origin)
    stats = widen_rows(state.stats, k)
    return state._replace(prior=wide, posterior=_m_step(wide, stats), stats=stats)
