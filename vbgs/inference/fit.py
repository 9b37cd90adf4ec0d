"""Batch CAVI: iterations of :func:`vbgs.inference.model.update` on all the data, with
optional re-seeding (:mod:`vbgs.inference.reassign`).

Kept apart from :mod:`vbgs.inference.model` because it combines the model with
:mod:`vbgs.inference.reassign`. Streams (each batch seen once) have one loop, the scene
learner's: :func:`vbgs.mapping.update_points`.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.model import (
    Mixture,
    PriorConfig,
    State,
    _update,
    bucket_size,
    check_points_host,
    chunk_size,
    padded_batch,
    start,
    update,
)
from vbgs.inference.reassign import MIN_COUNT, reassign, reassign_centred


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
    (:func:`vbgs.inference.reassign.reassign`): a move outside CAVI that helps random
    initialisations; the ELBO then usually, but not provably, keeps increasing.

    The whole fit is one compiled function (a ``lax.while_loop`` over the iterations):
    one executable per data size, loaded from the persistent cache by a later process.
    ``callback(t, state, info)`` observes each iteration; with it the iterations run
    one by one from the host (:func:`fit_steps`, the slow reference: same result).
    """
    if callback is not None:
        return fit_steps(prior, xyz, rgb, iters=iters, tol=tol, config=config, key=key,
                         callback=callback)
    _check_iters(iters)
    xyz, rgb = check_points_host(xyz, rgb)
    if xyz.shape[1] != prior.dim:
        raise ValueError(f"points are {xyz.shape[1]}-D but the model is {prior.dim}-D")
    n = xyz.shape[0]
    size = bucket_size(n)
    x, c, w = padded_batch(xyz, rgb, prior.origin, size, prior.alpha.dtype)
    reseed = key is not None
    key = jax.random.key(0) if key is None else key  # unused without re-seeding
    posterior, trace, count, converged, moved = _fit_compiled(
        prior, x, c, w, key, tol, MIN_COUNT, iters=int(iters), n=n,
        colour_noise=float(config.colour_noise), chunk=chunk_size(size, prior.n_components),
        reseed=reseed)
    count = int(count)
    return posterior, FitInfo(np.asarray(trace)[:count].astype(np.float64), count,
                              bool(converged), int(moved))


def _check_iters(iters) -> None:
    if not isinstance(iters, (int, np.integer)) or iters < 1:
        raise ValueError(f"iters must be a positive integer, got {iters!r}")


@partial(jax.jit, static_argnames=("iters", "n", "colour_noise", "chunk", "reseed"))
def _fit_compiled(prior: Mixture, x, c, w, key, tol, min_count, *, iters: int, n: int,
                  colour_noise: float, chunk: int, reseed: bool):
    """:func:`fit_steps` as one function: centred padded points ``x [size, d]``,
    ``c [size, 3]``, ``w [size]`` whose first ``n`` rows are the data. Returns the
    posterior, the ELBO trace ``[iters]`` (first ``count`` entries set), ``count``,
    ``converged`` and the number of re-seeded components. The stopping test
    ``|elbo_t - elbo_{t-1}| <= tol |elbo_{t-1}|`` is made in the data's dtype (the host
    loop makes it in float64 on the same values: they differ only when the change is
    within rounding of the threshold). The prior is not returned (an input passed
    through to the outputs made XLA:CPU hang, see the note in ``vbgs.inference.model._update``)."""
    empty = start(prior).stats

    def body(carry):
        t, state, key, trace, moved, _ = carry
        posterior, stats, info = _update(State(state.prior, state.posterior, empty), x, c, w,
                                         None, "posterior", colour_noise, chunk)
        state = State(state.prior, posterior, stats)
        trace = trace.at[t].set(info.elbo)
        if reseed:  # on the data rows only, as reassign sees them in fit_steps
            key, sub = jax.random.split(key)
            state, rinfo = reassign_centred(state, x[:n], c[:n], info.point_loglik[:n], sub,
                                            min_count, colour_noise)
            moved = moved + rinfo.n_moved.astype(moved.dtype)  # int64 under x64
        prev = trace[jnp.maximum(t - 1, 0)]
        converged = (t > 0) & (jnp.abs(trace[t] - prev) <= tol * jnp.abs(prev))
        return t + 1, state, key, trace, moved, converged

    def more(carry):
        t, *_, converged = carry
        return (t < iters) & ~converged

    carry = (jnp.int32(0), start(prior), key, jnp.zeros((iters,), x.dtype), jnp.int32(0),
             jnp.bool_(False))
    t, state, _, trace, moved, converged = jax.lax.while_loop(more, body, carry)
    return state.posterior, trace, t, converged, moved


def fit_steps(
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
    """:func:`fit` one iteration at a time from the host, through :func:`update` and
    :func:`vbgs.inference.reassign.reassign` (the slow, obvious reference of the compiled fit;
    ``callback(t, state, info)`` observes each iteration)."""
    _check_iters(iters)
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
