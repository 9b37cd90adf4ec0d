"""The streaming variational bound: what a stream's per-batch objective means.

When batch t arrives the model before it, ``q_{t-1}`` (the posterior after batches
< t, with any components grown for batch t at their prior), plays the role of the
prior, and learning the batch gives ``q_t``. For any ``q_t``,

    log p(x_t | x_<t) >= B_t = E_{q_t}[log p(x_t | theta)] - KL(q_t || q_{t-1}),

exactly so when ``q_{t-1}`` is the true posterior given x_<t (otherwise the bound is
the one assumed-density filtering maximises). The expectation is the mixture's local
bound ``sum_n log sum_k exp(l_nk)`` with ``l_nk = E_{q_t}[log pi_k + log N(x_n | mu_k,
Sigma_k) + log N(c_n | mu_c,k, sigma_c^2 I)]`` (the E-step's optimum over the
responsibilities). Summed over batches, ``sum_t B_t`` estimates a lower bound on
``log p(x_1, ..., x_T)``, the evidence of everything streamed: a number that means
the same whatever the order or the assignment mode, unlike the ELBO of
:func:`vbgs.inference.model.update` (under prior assignment its KL term is 0; under posterior
assignment it mixes one batch with a posterior built from all earlier ones).

Built on :mod:`vbgs.inference.model`'s public functions only: the expected log-likelihood is
the ``log sum_k exp`` of :func:`vbgs.inference.model.e_step` under ``q_t`` (the ELBO
:func:`vbgs.inference.model.update` reports for a state whose reference model and posterior
are both ``q_t``, whose KL term ``KL(q_t || q_t)`` is 0 up to rounding; tests hold the two
equal). The expected log-likelihood is one compiled function, its points padded to the
power of two that holds them: a stream's batches of many sizes compile it once per octave
(the update's own buckets, eight per octave, compiled the bound anew for most frames of
a stream: 41 of 100 s of compilation in a tiny ``fit-scene`` run).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference import candidates, model

# The smallest padded size of a bound's batch: smaller batches cost little either way,
# and each size below it would be a compilation of its own.
MIN_PADDED = 1024


class BatchBound(NamedTuple):
    """B_t and its two terms, in nats (Python floats)."""

    expected_loglik: float  # sum_n log sum_k exp(l_nk) under q_t
    kl: float  # KL(q_t || q_{t-1})
    bound: float  # expected_loglik - kl
    n_points: int


def expected_loglik(q: model.Mixture, xyz, rgb, *, config: model.PriorConfig = model.PriorConfig(),
                    estep: model.EStep = "dense",
                    n_candidates: int = candidates.DEFAULT_CANDIDATES) -> float:
    """``sum_n log sum_k exp(l_nk)`` of the batch ``xyz [n, d]``, ``rgb [n, 3]`` under
    ``q`` (sparse: over each point's candidates, a lower bound on the dense value)."""
    return _expected_loglik(q, xyz, rgb, config, estep, n_candidates)


def batch_bound(before: model.Mixture, after: model.Mixture, xyz, rgb, *,
                config: model.PriorConfig = model.PriorConfig(), estep: model.EStep = "dense",
                n_candidates: int = candidates.DEFAULT_CANDIDATES) -> BatchBound:
    """``B_t`` for the batch ``xyz [n, d]``, ``rgb [n, 3]`` learned from ``before``
    (``q_{t-1}``) to ``after`` (``q_t``); see the module docstring."""
    ell = _expected_loglik(after, xyz, rgb, config, estep, n_candidates)
    # op by op, outside the E-step's compiled function: compiled next to it, the LU of
    # q_{t-1}'s scales ran beside q_t's and both LAPACK calls waited on the 2-core thread
    # pool for good (a 128 px, 20k component fit-scene hung; see vbgs/__init__.py)
    kl = float(model.kl(after, before, config.colour_noise))
    return BatchBound(ell, kl, ell - kl, int(len(xyz)))


def padded_size(n: int) -> int:
    """The rows a bound's batch of ``n`` points is padded to: the power of two that holds
    them, at least :data:`MIN_PADDED` (one compilation per octave of batch size)."""
    return max(MIN_PADDED, 1 << (max(n, 1) - 1).bit_length())


def _expected_loglik(q: model.Mixture, xyz, rgb, config: model.PriorConfig,
                     estep: model.EStep, n_candidates: int) -> float:
    """``sum_n lse_n`` under ``q`` as a Python float: the points padded on the host
    (:func:`padded_size`; weight 0), the sparse E-step's candidates of the real points
    from a KD-tree over ``q``'s means."""
    if estep not in ("dense", "sparse"):
        raise ValueError(f"unknown E-step {estep!r}: use 'dense' or 'sparse'")
    xyz, rgb = model.check_points_host(xyz, rgb)
    n, d = xyz.shape
    if d != q.dim:
        raise ValueError(f"points are {d}-D but the model is {q.dim}-D")
    size = padded_size(n)
    x, c, w = model.padded_batch(xyz, rgb, q.origin, size, q.alpha.dtype)
    cand = None
    if estep == "sparse":
        cand = np.zeros((size, int(min(n_candidates, q.n_components))), np.int32)
        cand[:n] = candidates.nearest_components(q.space.mean, x[:n], n_candidates)
        chunk = model.chunk_size(size, cand.shape[1] * (d * d + d + 4))
    else:
        chunk = model.chunk_size(size, q.n_components)
    return float(_compiled_loglik(q, x, c, w, cand, float(config.colour_noise), chunk))


@partial(jax.jit, static_argnames=("colour_noise", "chunk"))
def _compiled_loglik(q: model.Mixture, x, c, w, cand, colour_noise: float, chunk: int):
    _, lse = model.e_step(q, x, c, w, colour_noise, chunk, cand)
    return jnp.sum(jnp.where(w > 0, lse * w, 0.0))  # padding's candidates are arbitrary


class StreamBound(NamedTuple):
    """The running sum of ``B_t`` over a stream, with its terms."""

    bound: float = 0.0
    expected_loglik: float = 0.0
    kl: float = 0.0
    n_points: int = 0
    per_batch: tuple = ()  # B_t per batch

    def add(self, b: BatchBound) -> StreamBound:
        return StreamBound(self.bound + b.bound, self.expected_loglik + b.expected_loglik,
                           self.kl + b.kl, self.n_points + b.n_points,
                           self.per_batch + (b.bound,))

    def summary(self) -> dict:
        """JSON fields: the total bound, per point, its terms and the per-batch trace."""
        n = max(self.n_points, 1)
        return {"stream_bound": self.bound, "stream_bound_per_point": self.bound / n,
                "stream_expected_loglik": self.expected_loglik, "stream_kl": self.kl,
                "stream_bound_per_batch": list(self.per_batch)}
