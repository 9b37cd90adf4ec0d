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

Built on :mod:`vbgs.inference.model`'s public functions only: the expected log-likelihood is the
ELBO :func:`vbgs.inference.model.update` reports for a state whose reference model and
posterior are both ``q_t`` (then its KL term is ``KL(q_t || q_t) = 0``).
"""

from __future__ import annotations

from typing import NamedTuple

from vbgs.inference import candidates, model


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
    _, info = model.update(model.start(q, config), xyz, rgb, assign="prior", estep=estep,
                           n_candidates=n_candidates)
    return float(info.elbo)


def batch_bound(before: model.Mixture, after: model.Mixture, xyz, rgb, *,
                config: model.PriorConfig = model.PriorConfig(), estep: model.EStep = "dense",
                n_candidates: int = candidates.DEFAULT_CANDIDATES) -> BatchBound:
    """``B_t`` for the batch ``xyz [n, d]``, ``rgb [n, 3]`` learned from ``before``
    (``q_{t-1}``) to ``after`` (``q_t``); see the module docstring."""
    ell = expected_loglik(after, xyz, rgb, config=config, estep=estep,
                          n_candidates=n_candidates)
    kl = float(model.kl(after, before, config.colour_noise))
    return BatchBound(ell, kl, ell - kl, int(len(xyz)))


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
