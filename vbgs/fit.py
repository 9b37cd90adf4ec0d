"""Loops over :func:`vbgs.model.update`: batch CAVI and streaming, with optional reassign.

Kept apart from :mod:`vbgs.model` because they combine the model with
:mod:`vbgs.reassign`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import NamedTuple

import jax
import numpy as np

from vbgs.candidates import DEFAULT_CANDIDATES
from vbgs.model import Assign, EStep, Info, Mixture, PriorConfig, State, start, update
from vbgs.reassign import reassign
from vbgs.stepper import Stepper


class FitInfo(NamedTuple):
    elbo: np.ndarray  # [iterations]
    iterations: int
    converged: bool
    moved: int  # components re-seeded in total


def fit(
    prior: Mixture,
    xyz,
    rgb,
    *,
    iters: int = 10,
    tol: float = 1e-6,
    config: PriorConfig = PriorConfig(),
    key: jax.Array | None = None,
    callback: Callable | None = None,
) -> tuple[Mixture, FitInfo]:
    """Batch CAVI on all the data: alternate E- and M-steps until the relative ELBO
    change falls below ``tol`` or ``iters`` iterations have run.

    Each iteration is one :func:`update` under the current posterior from empty
    statistics. ``elbo[t]`` is the ELBO of the posterior after t iterations (elbo[0]
    is the prior's). Without ``key`` this is plain CAVI and the ELBO never decreases.
    With ``key``, unused components are re-seeded after every iteration
    (:func:`vbgs.reassign.reassign`): a move outside CAVI that helps random
    initialisations; the ELBO then usually, but not provably, keeps increasing.
    ``callback(t, state, info)`` observes each iteration.
    """
    if not isinstance(iters, (int, np.integer)) or iters < 1:
        raise ValueError(f"iters must be a positive integer, got {iters!r}")
    state = start(prior, config)
    empty = state.stats
    trace, moved, converged = [], 0, False
    for t in range(iters):
        state, info = update(state._replace(stats=empty), xyz, rgb, assign="posterior")
        trace.append(float(info.elbo))
        if key is not None:
            key, sub = jax.random.split(key)
            state, rinfo = reassign(state, xyz, rgb, info.point_loglik, key=sub)
            moved += int(rinfo.n_moved)
        if callback is not None:
            callback(t, state, info)
        if t > 0 and abs(trace[-1] - trace[-2]) <= tol * abs(trace[-2]):
            converged = True
            break
    return state.posterior, FitInfo(np.asarray(trace), len(trace), converged, moved)


def stream(
    prior: Mixture,
    batches: Iterable[tuple[np.ndarray, np.ndarray]],
    *,
    assign: Assign = "prior",
    config: PriorConfig = PriorConfig(),
    key: jax.Array | None = None,
    callback: Callable | None = None,
    estep: EStep = "dense",
    n_candidates: int = DEFAULT_CANDIDATES,
) -> State:
    """Continual learning: each ``(xyz, rgb)`` batch is seen once, through
    :func:`update`; nothing is replayed.

    With ``key``, before each batch is learned the unused components are re-seeded
    onto its worst-explained points (:func:`vbgs.reassign.reassign`, scored under the
    assignment model), so new regions of the stream get fresh components. This costs
    one more E-step per batch and changes the reference model, so ``prior``
    assignment is then no longer order-invariant. ``callback(i, state, info)``
    observes each batch.

    Without ``key`` the batches go through one :class:`vbgs.stepper.Stepper` (terms and
    candidate structure built once, one compiled step); with ``key`` the reference
    model changes every batch and each goes through :func:`update`. ``estep`` and
    ``n_candidates`` are as in :func:`update`.
    """
    state = start(prior, config)
    step = None if key is not None else Stepper(prior, assign=assign, config=config,
                                                 estep=estep, n_candidates=n_candidates)
    for i, (xyz, rgb) in enumerate(batches):
        if step is not None:
            state, info = step(state, xyz, rgb)
            if callback is not None:  # the caller observes: copy its [n] log-likelihoods
                info = Info(info.elbo, np.asarray(info.point_loglik)[: len(xyz)])
        else:
            key, sub = jax.random.split(key)
            _, scored = update(state, xyz, rgb, assign=assign, estep=estep,
                               n_candidates=n_candidates)
            state, _ = reassign(state, xyz, rgb, scored.point_loglik, key=sub)
            state, info = update(state, xyz, rgb, assign=assign, estep=estep,
                                 n_candidates=n_candidates)
        if callback is not None:
            callback(i, state, info)
    return state
