"""vbgs.inference.merge: freeing slots by merging neighbours, exactly in the statistics."""

import warnings

import jax
import numpy as np
import pytest

from vbgs.inference import expfam, grow, merge, model
from vbgs.inference.model import PriorConfig

CONFIG = PriorConfig()


def two_clusters_state(seed=0, gap=0.05, colours=((0.5, 0.2, 0.1), (0.5, 0.2, 0.1))):
    """Four components: 0 and 1 on two halves of one patch (one colour unless told),
    2 and 3 far away on another patch; each learns its own points (one-hot)."""
    rng = np.random.default_rng(seed)
    centres = np.array([[0.0, 0.0, 0.0], [gap, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 2.0, 0.0]])
    cols = np.array([colours[0], colours[1], (0.1, 0.8, 0.1), (0.9, 0.9, 0.9)])
    xyz = np.concatenate([c + rng.normal(0, 0.03, (200, 3)) * [1, 1, 0.01] for c in centres])
    rgb = np.concatenate([np.tile(c, (200, 1)) for c in cols])
    label = np.repeat(np.arange(4), 200)
    prior = model.make_prior(centres.astype(np.float32), cols.astype(np.float32),
                             np.zeros(3, np.float32), 0.05, CONFIG)
    r = np.eye(4, dtype=np.float32)[label]
    stats = model.moments_to_stats(_moments(r, xyz.astype(np.float32), rgb), 3)
    state = model.start(prior, CONFIG)
    return state._replace(posterior=model.m_step(prior, stats), stats=stats), xyz, rgb, label


def _moments(r, x, c):
    """The summed feature moments [k, F] of one-hot responsibilities (model's layout)."""
    phi = np.asarray(model.features(x, c))
    return r.T @ phi


@pytest.mark.xla_default  # equal to the bit at XLA's default (tests/conftest.py)
def test_merged_statistics_are_the_union_of_both_components():
    state, xyz, rgb, label = two_clusters_state()
    empty = grow.empty_prior(4, state.prior.origin, 0.05, CONFIG)
    merged = merge.merge(state, np.array([[0, 1]]), empty)
    s, m = state.stats, merged.stats
    np.testing.assert_allclose(m.count[0], s.count[0] + s.count[1], rtol=1e-6)
    np.testing.assert_allclose(m.sum_x[0], s.sum_x[0] + s.sum_x[1], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(m.sum_xx[0], s.sum_xx[0] + s.sum_xx[1], rtol=1e-5, atol=1e-6)
    assert float(m.count[1]) == 0.0  # slot 1 is empty again ...
    assert not grow.is_active(merged.prior)[1]  # ... and takes no responsibility
    assert grow.is_active(merged.prior)[[0, 2, 3]].all()
    # the merged posterior mean is the mean of both clusters' points
    mean = np.asarray(merged.posterior.space.mean[0]) + np.asarray(merged.prior.origin)
    np.testing.assert_allclose(mean, xyz[label < 2].mean(0), atol=2e-3)
    # the untouched components keep their posterior exactly
    np.testing.assert_array_equal(np.asarray(merged.posterior.space.scale[2:]),
                                  np.asarray(state.posterior.space.scale[2:]))


def test_near_duplicates_cost_less_than_an_edge_of_colour_or_distance():
    state, *_ = two_clusters_state()
    counts = np.asarray(state.stats.count, np.float64)
    cost = merge.merge_costs(state.posterior, counts, np.array([[0, 1], [2, 3], [0, 2]]),
                             CONFIG.colour_noise)
    assert cost[0] < 0.01 * cost[1:].min()  # same patch and colour: ~100 nats, else >1e4
    assert 50 < cost[0] < 200
    red, _, _, _ = two_clusters_state(colours=((0.9, 0.1, 0.1), (0.1, 0.1, 0.9)))
    edge = merge.merge_costs(red.posterior, counts, np.array([[0, 1]]), CONFIG.colour_noise)
    assert edge[0] > 100 * cost[0]  # the same geometry across a colour edge


def test_two_components_without_points_are_never_merged_and_warn_nothing():
    state, *_ = two_clusters_state()
    counts = np.asarray(state.stats.count, np.float64)
    counts[[2, 3]] = 0.0  # two active slots whose points went elsewhere
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no 0/0 in the moment match
        cost = merge.merge_costs(state.posterior, counts, np.array([[0, 1], [2, 3]]),
                                 CONFIG.colour_noise)
    assert np.isfinite(cost[0]) and cost[1] == np.inf


def test_choose_pairs_takes_disjoint_pairs_cheapest_first():
    state, *_ = two_clusters_state()
    counts = np.asarray(state.stats.count, np.float64)
    active = np.ones(4, bool)
    pairs = merge.choose_pairs(state.posterior, counts, active, 1, CONFIG.colour_noise)
    assert pairs.tolist() == [[0, 1]]
    pairs = merge.choose_pairs(state.posterior, counts, active, 5, CONFIG.colour_noise)
    assert sorted(pairs.reshape(-1).tolist()) == [0, 1, 2, 3]  # two pairs, disjoint
    none = merge.choose_pairs(state.posterior, counts, np.eye(4, dtype=bool)[0], 3,
                              CONFIG.colour_noise)
    assert none.shape == (0, 2)  # one active component: nothing to merge


@pytest.mark.parametrize("n", [1, 7, 60, 200, 400])
def test_cheapest_disjoint_equals_the_greedy_over_the_whole_sorted_order(n):
    """The head-first choice (a partition, the whole order only when the head lacks
    ``n`` disjoint pairs) against the greedy written out over every pair in stable
    order: the same pairs, ties (costs rounded to a few values) and infinite costs
    included; from n = 200 the 300 slots hold fewer than n disjoint pairs (the whole
    order read)."""
    rng = np.random.default_rng(n)
    k = 300
    pairs = np.unique(np.sort(rng.integers(0, k, (1500, 2)), 1), axis=0)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    cost = np.round(rng.exponential(1.0, len(pairs)), 1)
    cost[rng.random(len(pairs)) < 0.05] = np.inf
    got = merge.cheapest_disjoint(pairs, cost, k, n)
    assert np.array_equal(got, _greedy(pairs, np.argsort(cost, kind="stable"), n))


def _greedy(pairs, order, n=None):
    """The greedy written out: each pair in ``order`` unless an earlier one took an end."""
    used, want = set(), []
    for i in order:
        a, b = pairs[i]
        if a in used or b in used:
            continue
        used |= {a, b}
        want.append(i)
        if len(want) == n:
            break
    return pairs[np.asarray(want, np.int64)].reshape(-1, 2)


@pytest.mark.parametrize("n", [None, 3, 40])
def test_the_greedy_rounds_hand_a_long_chain_to_the_pair_by_pair_loop(n):
    """A path of pairs each dearer than the one before settles one pair a round: past
    ``ROUNDS`` rounds the rest is taken one by one, and the answer is still the
    greedy's (every other pair of the path, first ``n``); a random order over the same
    path too."""
    m = 5 * merge.ROUNDS
    path = np.stack([np.arange(m), np.arange(1, m + 1)], 1)
    ordered = merge._disjoint(path, np.arange(m), m + 1, n)
    assert np.array_equal(ordered, _greedy(path, np.arange(m), n))
    assert np.array_equal(ordered[:, 0], np.arange(0, m, 2)[:n])
    shuffled = np.random.default_rng(0).permutation(m)
    assert np.array_equal(merge._disjoint(path, shuffled, m + 1, n),
                          _greedy(path, shuffled, n))


def test_neighbour_pairs_are_the_active_components_with_their_nearest_once():
    """Against the pairs written out from all distances: the tree search and the rows'
    pairs sorted row by row (merge.listed_pairs) give each pair once, in order."""
    rng = np.random.default_rng(2)
    means = rng.uniform(-1.0, 1.0, (300, 3)).astype(np.float32)
    active = rng.random(300) < 0.8
    posterior = model.make_prior(means, np.zeros((300, 3), np.float32),
                                 np.zeros(3, np.float32), 0.05, CONFIG)
    got = merge.neighbour_pairs(posterior, active, 4)
    idx = np.flatnonzero(active)
    x = means[idx].astype(np.float64)
    dist = ((x[:, None] - x[None]) ** 2).sum(-1)
    near = np.argsort(dist, axis=1, kind="stable")[:, 1:5]
    # b among a's nearest with a < b (not a among b's alone: the docstring's rule)
    want = sorted({(a, b) for a in range(len(idx)) for b in near[a] if a < b})
    assert np.array_equal(got, idx[np.asarray(want)])


def test_merge_rows_sums_any_per_component_table():
    stats = expfam.zero_stats(3, 3, noisy=True)._replace(
        count=jax.numpy.array([1.0, 2.0, 4.0]))
    out = merge.merge_rows(stats, np.array([[2, 0]]))
    assert np.asarray(out.count).tolist() == [0.0, 2.0, 5.0]
    assert out.sum_noise.shape == (3, 3, 3)


def _plain_cost(posterior, counts, a, b, colour_noise):
    """The module docstring's cost of merging ``a`` and ``b``, one pair at a time
    (float64 matrices, LAPACK's log-determinants): the reference for merge_costs."""
    d = posterior.space.mean.shape[-1]

    def moments(i):
        scale = np.asarray(posterior.space.scale[i], np.float64)
        return (np.asarray(posterior.space.mean[i], np.float64),
                scale / (float(posterior.space.dof[i]) - d - 1.0))

    (ma, ca), (mb, cb) = moments(a), moments(b)
    na, nb = counts[a], counts[b]
    m = (na * ma + nb * mb) / (na + nb)
    c = (na * (ca + np.outer(ma - m, ma - m)) + nb * (cb + np.outer(mb - m, mb - m))) / (na + nb)
    logdet = lambda s: np.linalg.slogdet(s)[1]  # noqa: E731
    colour = np.asarray(posterior.colour.mean, np.float64)
    gap = ((colour[a] - colour[b]) ** 2).sum()
    return (0.5 * ((na + nb) * logdet(c) - na * logdet(ca) - nb * logdet(cb))
            + na * nb / (na + nb) * gap / (2.0 * colour_noise**2))


@pytest.mark.parametrize("dim", [2, 3])
def test_merge_costs_are_the_plain_formula_pair_by_pair(dim):
    """merge_costs' entry-major arithmetic (each component's moments found once) gives
    the cost written out one pair at a time, in 2-D (an image) and 3-D; a few pairs
    (their own components' moments only) give the bits of the same pairs among many."""
    rng = np.random.default_rng(3)
    k = 40
    means = rng.normal(0, 1, (k, dim)).astype(np.float32)
    colours = rng.uniform(0, 1, (k, 3)).astype(np.float32)
    prior = model.make_prior(means, colours, np.zeros(dim, np.float32), 0.05, CONFIG)
    x = np.repeat(means, 30, 0) + rng.normal(0, 0.05, (30 * k, dim)) * rng.uniform(
        0.2, 1, dim)
    rgb = np.repeat(colours, 30, 0)
    r = np.eye(k, dtype=np.float32)[np.repeat(np.arange(k), 30)]
    stats = model.moments_to_stats(_moments(r, x.astype(np.float32), rgb), dim)
    posterior = model.m_step(prior, stats)
    counts = np.asarray(stats.count, np.float64)
    pairs = np.stack(np.triu_indices(k, 1), 1)
    cost = merge.merge_costs(posterior, counts, pairs, CONFIG.colour_noise)
    want = [_plain_cost(posterior, counts, a, b, CONFIG.colour_noise) for a, b in pairs]
    np.testing.assert_allclose(cost, want, rtol=1e-9, atol=1e-6)
    few = pairs[[5, 77, 300]]
    assert merge.merge_costs(posterior, counts, few, CONFIG.colour_noise).tobytes() == \
        cost[[5, 77, 300]].tobytes()
