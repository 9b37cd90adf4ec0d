"""The streaming bound (vbgs.inference.bound): a known answer and an independent path."""

import jax
import numpy as np
import pytest

from vbgs.inference import bound, model
from vbgs.inference.expfam import zero_stats


def blob(n: int, seed: int):
    rng = np.random.default_rng(seed)
    xyz = rng.normal([0.3, -0.2, 1.0], [0.2, 0.1, 0.3], (n, 3)).astype(np.float32)
    rgb = np.clip(rng.normal(0.5, 0.05, (n, 3)), 0, 1).astype(np.float32)
    return xyz, rgb


def streamed_bound(prior, batches, assign="prior"):
    state, total = model.start(prior), bound.StreamBound()
    for xyz, rgb in batches:
        before = state.posterior
        state, _ = model.update(state, xyz, rgb, assign=assign)
        total = total.add(bound.batch_bound(before, state.posterior, xyz, rgb))
    return total


def test_one_component_bound_is_the_evidence_whatever_the_split():
    """With one component every update is the exact conjugate posterior, so each B_t is
    log p(x_t | x_<t) and their sum is log p(x_1..T): the same for 1, 4 or 16 batches."""
    xyz, rgb = blob(256, 0)
    prior = model.init(xyz, rgb, 1, key=jax.random.key(0), scheme="data")
    totals = [streamed_bound(prior, zip(np.array_split(xyz, m), np.array_split(rgb, m),
                                        strict=True)).bound for m in (1, 4, 16)]
    np.testing.assert_allclose(totals, totals[0], rtol=2e-4)
    assert len(streamed_bound(prior, [(xyz[:8], rgb[:8])] * 3).per_batch) == 3


def test_batch_bound_equals_the_elbo_of_a_batch_fit():
    """One batch from the prior: B_1 = sum_n lse(q_1) - KL(q_1 || prior), the ELBO that
    update reports for q_1 on all the data under posterior assignment (other path)."""
    xyz, rgb = blob(300, 1)
    prior = model.init(xyz, rgb, 12, key=jax.random.key(1), scheme="data")
    q1, _ = model.update(model.start(prior), xyz, rgb, assign="posterior")
    b = bound.batch_bound(prior, q1.posterior, xyz, rgb)
    empty = zero_stats(12, 3)
    _, info = model.update(model.State(prior, q1.posterior, empty), xyz, rgb,
                           assign="posterior")
    assert b.bound == pytest.approx(float(info.elbo), rel=1e-5)
    assert b.kl > 0 and b.n_points == 300
    assert b.bound == pytest.approx(b.expected_loglik - b.kl)


def test_sparse_expected_loglik_is_below_the_dense_one():
    xyz, rgb = blob(200, 2)
    q = model.init(xyz, rgb, 64, key=jax.random.key(2), scheme="data")
    dense = bound.expected_loglik(q, xyz, rgb, estep="dense")
    sparse = bound.expected_loglik(q, xyz, rgb, estep="sparse", n_candidates=4)
    assert sparse <= dense + 1e-3 * abs(dense)



@pytest.mark.parametrize("estep", ["dense", "sparse"])
def test_bound_terms_equal_the_updates_elbo_and_the_kl(estep):
    """The compiled terms (points padded to a power of two) equal what the bound was
    first built from, to float32 rounding: the ELBO model.update reports for a state
    whose reference and posterior are both q_t, and model.kl run op by op. (The shapes
    of the test above: 200 points, padded to 1024 here and to 200 by model.update.)"""
    xyz, rgb = blob(200, 2)
    prior = model.init(xyz, rgb, 64, key=jax.random.key(2), scheme="data")
    after, _ = model.update(model.start(prior), xyz, rgb, estep=estep, n_candidates=4)
    b = bound.batch_bound(prior, after.posterior, xyz, rgb, estep=estep, n_candidates=4)
    _, info = model.update(model.start(after.posterior), xyz, rgb, estep=estep,
                           n_candidates=4)
    assert b.expected_loglik == pytest.approx(float(info.elbo), rel=1e-6, abs=1e-3)
    noise = model.PriorConfig().colour_noise
    assert b.kl == pytest.approx(float(model.kl(after.posterior, prior, noise)), rel=1e-5)
    assert b.kl > 0 and b.n_points == 200
