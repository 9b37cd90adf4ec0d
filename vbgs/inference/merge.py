"""When the budget is spent: merge the neighbours that the data tell apart least.

A map of fixed capacity K that keeps meeting new ground (a walk that never comes back)
runs out of empty slots. Leaving the new ground without components draws it as
background; stretching old components over it draws needles. Merging frees slots
instead, where it costs least: two components become one, and the slot of the second
is emptied for new ground (:mod:`vbgs.inference.grow`).

Merging is exact in a conjugate model's statistics: the merged component's sufficient
statistics are the sum of the two (counts, first and second moments, colours, noise),
so its posterior is the one it would have had if every point of both had gone to it.
What a merge costs is how much worse one Gaussian explains both components' points
than two did: with counts ``n_a, n_b``, expected covariances ``S_a, S_b`` and the
moment-matched ``S`` of the union,

    cost = (n_a + n_b) log|S| / 2 - n_a log|S_a| / 2 - n_b log|S_b| / 2
           + n_a n_b / (n_a + n_b) |c_a - c_b|^2 / (2 sigma_c^2)

(nats; the loss in expected log-likelihood of the points under a moment-matched
Gaussian, spatial and colour). Components with little evidence cost little, as do
near-duplicates on one surface of one colour; a merge across an edge of colour costs
much. Each component is paired with its :data:`NEIGHBOURS` nearest (the only merges a
surface allows), and disjoint pairs are taken cheapest first.

The merged slot's prior row (the reference that assigns points under prior
assignment) is the moment match of the two rows, weighted by their counts, so the
merged component assigns the ground both did; the freed slot returns to the empty
slot of :func:`vbgs.inference.grow.empty_prior`.

Merges scored by the bound (``components="auto"``, :func:`vbgs.mapping.mapper._auto_room`). With no
budget to free, a merge must earn its place: it is taken when it raises the variational
bound, the objective every update maximises and :mod:`vbgs.inference.bound` reports.
Give each point to one component (the responsibilities' entropy, ~0 for components a
point tells apart, is left out). Then the optimum over ``q`` of the bound's terms for
component k's points, ``E_q[log p(points_k | theta_k)] - KL(q_k || p_k)``, is their log
marginal likelihood ``E_k`` (NIW spatial, Normal colour: ``expfam.niw_log_evidence``,
``expfam.colour_log_evidence``), and over ``q(pi)`` the mixing weights' terms give the
Dirichlet-multinomial ``sum_k [lnG(a_k + N_k) - lnG(a_k)] + lnG(A) - lnG(A + N)``
(``A = sum_k a_k``, ``N`` all points). Merging ``b`` into ``a`` (statistics summed,
prior rows moment-matched as above, ``b``'s slot back to an empty one with ``a_b ~ 0``)
changes the bound by

    gain = E_ab - E_a - E_b + a_b (psi(A + N) - psi(A))

(the last term the first-order change of ``lnG(A) - lnG(A + N)`` when ``A`` loses
``a_b``; ``E`` includes the Dirichlet part ``lnG(a + N) - lnG(a)``). ``E_ab - E_a - E_b``
is the data's verdict, both ways: one Gaussian explaining points that two explained
better costs likelihood, and each component pays its own Occam factor (its KL to its
prior, about ``(p/2) log N_k`` nats for p parameters) that a merge saves. So ``gain > 0``
exactly when one component explains the pair's points better than two, by the bound;
:func:`bound_pairs` takes such pairs, best first, disjoint. Measured on the object's
validation views (128 px, 60 frames, ``auto`` at 2 points per cell: `python -m
experiments.run tune --scene object --components auto --grid growth.merge=true,false`):
24.55 dB with 9009 components drawn with these merges, 23.59 dB with 15196 without; the
merges drop the components that births on sparse ground start and the data never back.
On the walk (the same command with ``--scene walk``) they cost: 17.87 dB with 36936
components, 19.64 dB with 75978 without (depth L1 1.16 against 0.68). The bound scores
points, not pictures: a merge the points allow can still open holes in views from
elsewhere (far ground, seen coarsely and from one side). Since ``auto`` splits
(the rule of the time, ``refinement_levels``) these merges cost pictures everywhere
(0.6-1.9 dB on the three scenes' validation views) and are off by default
(``growth.auto_merge_every = 0``; figures in :mod:`vbgs.components`).

Precision: costs are computed on the host in float64 (log-determinants of nearly flat
3x3 covariances differ in their last float32 digits); the merged statistics are sums,
exact to float32 rounding.
"""

from __future__ import annotations

from functools import partial

import jax
import numpy as np
from scipy.special import digamma

from vbgs.inference import expfam
from vbgs.inference.candidates import means_tree
from vbgs.inference.grow import _m_step  # compiled: one executable, shared with growth
from vbgs.inference.model import Mixture, State, m_step
from vbgs.inference.precision import logdet3

# Each component may merge with one of its this many nearest components (by mean).
NEIGHBOURS = 4
# cheapest_disjoint sorts the pairs cheaper than the HEAD * n-th first (a cost rule: the
# room's rounds at 640 x 480 take n disjoint pairs from the cheapest 1.5 n).
HEAD = 4


def _moments(space: expfam.NIW, rows: np.ndarray | None = None):
    """Means ``[d, m]`` and expected covariances ``[d, d, m]`` of the NIW rows ``rows``
    (None: all), in float64 on the host and entry-major: each entry of every row in one
    contiguous array (:func:`vbgs.inference.expfam.niw_expected_covariance` on the
    rows)."""
    rows = slice(None) if rows is None else rows
    q = expfam.NIW(*(np.asarray(field)[rows].astype(np.float64) for field in space))
    return (np.ascontiguousarray(q.mean.T),
            np.ascontiguousarray(expfam.niw_expected_covariance(q).transpose(1, 2, 0)))


def _union(wa, ma, ca, wb, mb, cb):
    """The moment match of two weighted Gaussians, entry-major (weights ``[m]``, means
    ``[d, m]``, covariances ``[d, d, m]``): mean ``[d, m]``, covariance ``[d, d, m]``.
    Entry-major because numpy's loops then run over the ``m`` rows, not over an axis of
    ``d``: 200k pairs' unions took 87 ms as ``[m, d, d]``."""
    w = wa + wb
    m = (wa * ma + wb * mb) / w
    da, db = ma - m, mb - m
    d = len(m)
    c = np.empty((d, d, len(w)))
    for i in range(d):  # entry by entry: broadcasting [d, 1, m] by [1, d, m] is slower
        for j in range(d):
            c[i, j] = (wa * (ca[i, j] + da[i] * da[j]) + wb * (cb[i, j] + db[i] * db[j])) / w
    return m, c


def _logdets(c: np.ndarray) -> np.ndarray:
    """``log |det c|`` ``[m]`` of the entry-major ``c [d, d, m]`` (float64): for d = 3
    elementwise (:func:`vbgs.inference.precision.logdet3`; a batched LAPACK call costs
    ten times more), else by ``slogdet``. The absolute value, as ``slogdet``'s: a thin
    component's float32 posterior scale can come out slightly indefinite, and clamping
    its determinant instead (so it never merged) lost 0.6-0.9 dB on the room's
    validation views."""
    s = c.transpose(2, 0, 1)
    return logdet3(s, floor=1e-300) if len(c) == 3 else np.linalg.slogdet(s)[1]


def merge_costs(posterior: Mixture, counts: np.ndarray, pairs: np.ndarray,
                colour_noise: float) -> np.ndarray:
    """``[m]`` nats: the cost (module docstring) of merging each row of ``pairs [m, 2]``
    (component indices) of ``posterior``, whose components hold ``counts [k]`` points.
    Each component's moments and log-determinant are found once, for the components the
    pairs name (all of them when the pairs name most), and gathered for the pairs."""
    a, b = pairs[:, 0], pairs[:, 1]
    na, nb = counts[a], counts[b]
    rows = None
    if 4 * len(pairs) < posterior.n_components:  # few pairs: their own components only
        rows, pairs = np.unique(pairs, return_inverse=True)
        pairs = pairs.reshape(-1, 2)
    mean, cov = _moments(posterior.space, rows)
    own = _logdets(cov)
    ia, ib = pairs[:, 0], pairs[:, 1]
    empty = na + nb <= 0  # two components without points: no cost defined, never merged
    _, c = _union(np.where(empty, 1.0, na), mean[:, ia], np.take(cov, ia, axis=2),
                  np.where(empty, 1.0, nb), mean[:, ib], np.take(cov, ib, axis=2))
    space = 0.5 * ((na + nb) * _logdets(c) - na * own[ia] - nb * own[ib])
    colour = np.asarray(posterior.colour.mean, np.float64).T  # entry-major, as above
    gap = ((colour[:, a] - colour[:, b]) ** 2).sum(0)
    cost = space + na * nb / np.maximum(na + nb, 1e-12) * gap / (2.0 * colour_noise**2)
    return np.where(empty, np.inf, cost)


def choose_pairs(posterior: Mixture, counts: np.ndarray, active: np.ndarray, n: int,
                 colour_noise: float, neighbours: int = NEIGHBOURS) -> np.ndarray:
    """Up to ``n`` disjoint pairs ``[p, 2]`` of active components (``active [k]`` bool),
    each with one of its ``neighbours`` nearest, cheapest merge first (greedy: a pair is
    taken unless a cheaper one took one of its components; matching the pairs cheapest
    for both ends instead, in vectorised rounds, lost 0.6 dB on the room's validation
    views for 10 ms a merge)."""
    if n <= 0:
        return np.zeros((0, 2), np.int64)
    pairs = neighbour_pairs(posterior, active, neighbours)
    if len(pairs) == 0:
        return pairs
    cost = merge_costs(posterior, counts, pairs, colour_noise)
    return cheapest_disjoint(pairs, cost, posterior.n_components, n)


def cheapest_disjoint(pairs: np.ndarray, cost: np.ndarray, k: int, n: int) -> np.ndarray:
    """Up to ``n`` disjoint pairs of ``pairs [p, 2]`` (slots of ``k``), cheapest ``cost
    [p]`` first (ties in the pairs' order). The greedy choice reads its order only as far
    as it takes ``n`` pairs, so the pairs cheaper than the ``HEAD * n``-th cheapest are
    sorted first (a partition, not a sort of all ``p``: 10 against 35 ms for 3000 of
    the room's 200k pairs at 640 x 480), and all of them only when those do not hold
    ``n`` disjoint pairs."""
    if HEAD * n < len(cost):
        head = np.flatnonzero(cost < np.partition(cost, HEAD * n)[HEAD * n])
        chosen = _disjoint(pairs, head[np.argsort(cost[head], kind="stable")], k, n)
        if len(chosen) == n:  # what the whole order gives: it starts with the head's
            return chosen
    return _disjoint(pairs, np.argsort(cost, kind="stable"), k, n)


def neighbour_pairs(posterior: Mixture, active: np.ndarray,
                    neighbours: int = NEIGHBOURS) -> np.ndarray:
    """``[p, 2]`` the pairs ``(a, b)`` of active components (``active [k]`` bool; ``a``
    before ``b`` among them) in which ``b`` is among ``a``'s ``neighbours`` nearest (by
    mean), each once. A pair where only ``a`` is among ``b``'s nearest is not offered:
    the rule every stream so far was measured with (making it symmetric would change
    which components merge; not tried)."""
    idx = np.flatnonzero(active)
    if len(idx) < 2:
        return np.zeros((0, 2), np.int64)
    means = np.asarray(posterior.space.mean)[idx].astype(np.float64)
    k = min(neighbours + 1, len(idx))
    _, near = means_tree(means).query(means, k=k, workers=-1)
    return listed_pairs(idx, idx[np.asarray(near).reshape(len(idx), k)])


def listed_pairs(idx: np.ndarray, near: np.ndarray) -> np.ndarray:
    """``[p, 2]`` the pairs ``(a, b)``, ``a`` a slot of ``idx [m]`` (ascending) and ``b``
    among its nearest ``near [m, c]`` (slots, the first, itself as the tree lists it,
    left out) with ``a < b``, sorted: each pair once, as one row lists a slot once.
    Sorted row by row (``c`` entries each) rather than as one packed key over all of
    them: the same order (rows in slot order, each row's in slot order), a fifth of the
    time (one of the 640x480 room's rounds, 100k slots: 3 ms against 14)."""
    b = near[:, 1:].astype(np.int64)
    none = np.iinfo(np.int64).max
    b = np.sort(np.where(b > idx[:, None], b, none), axis=1)
    keep = b != none
    return np.stack([np.broadcast_to(idx[:, None], b.shape)[keep], b[keep]], 1)


def _disjoint(pairs: np.ndarray, order: np.ndarray, k: int, n: int | None = None
              ) -> np.ndarray:
    """Up to ``n`` (None: any number) pairs of ``pairs [p, 2]`` taken greedily in
    ``order``: a pair is taken unless an earlier one took one of its components.

    The greedy's answer, found in vectorised rounds: a pair that comes first, among the
    pairs still open, at both its components is one the greedy takes (every earlier
    pair at its ends was closed by a taken pair, so none of them was taken), and taking
    it closes every other pair at its ends (the greedy would skip them). Each round
    takes at least the first open pair. The first ``n`` taken in order are known once
    ``n`` taken pairs come before every open one. Merge costs of a map's neighbours
    settle in a few rounds (3 to 6 on the room at 640 x 480: 5 against 19 ms for 10,000
    pairs of 40,000 against the pair-by-pair loop); a chain of ever dearer pairs settles
    one pair a round, so after :data:`ROUNDS` rounds the open pairs are taken one by one
    (:func:`_one_by_one`)."""
    a, b = pairs[order, 0], pairs[order, 1]
    rank = np.arange(len(order))
    used, first = np.zeros(k, bool), np.empty(k, np.int64)
    taken = []
    for _ in range(ROUNDS):
        if len(rank) == 0 or (n is not None and taken
                              and (np.concatenate(taken) < rank[0]).sum() >= n):
            rank = rank[:0]
            break
        first[a] = first[b] = len(order)
        np.minimum.at(first, a, rank)
        np.minimum.at(first, b, rank)
        won = (first[a] == rank) & (first[b] == rank)
        taken.append(rank[won])
        used[a[won]] = used[b[won]] = True
        open_ = ~(used[a] | used[b])
        a, b, rank = a[open_], b[open_], rank[open_]
    if len(rank):
        taken.append(rank[_one_by_one(a, b, used, n)])
    chosen = np.sort(np.concatenate([np.zeros(0, np.int64), *taken]))
    return pairs[order[chosen[:n]]]


# _disjoint's vectorised rounds before the open pairs are taken one by one.
ROUNDS = 12


def _one_by_one(a: np.ndarray, b: np.ndarray, used: np.ndarray, n: int | None
                ) -> np.ndarray:
    """The greedy written out: which of the pairs ``(a, b)`` (in order) it takes, given
    the components ``used [k]`` taken before them (at most ``n``)."""
    taken = bytearray(used.tobytes())
    chosen = []
    for i, (pa, pb) in enumerate(zip(a.tolist(), b.tolist(), strict=True)):  # Python ints
        if taken[pa] or taken[pb]:
            continue
        taken[pa] = taken[pb] = 1
        chosen.append(i)
        if len(chosen) == n:
            break
    return np.asarray(chosen, np.int64)


def merge(state: State, pairs: np.ndarray, empty: Mixture) -> State:
    """``state`` with each pair ``(a, b)`` of ``pairs [p, 2]`` merged into slot ``a`` and
    slot ``b`` emptied (its prior row taken from ``empty``, a prior of empty slots:
    :func:`vbgs.inference.grow.empty_prior`); the posterior is the M-step of the new
    prior and statistics."""
    if len(pairs) == 0:
        return state
    a, b = pairs[:, 0], pairs[:, 1]
    prior, stats = state.prior, state.stats
    m, scale, colour_ab = _merged_prior_rows(prior, np.asarray(stats.count, np.float64), a, b)

    def put(field, rows_a, source_b):
        out = np.array(field)
        if rows_a is not None:
            out[a] = rows_a
        out[b] = np.asarray(source_b)[b]
        return jax.device_put(out)

    space = prior.space._replace(
        mean=put(prior.space.mean, m, empty.space.mean),
        kappa=put(prior.space.kappa, None, empty.space.kappa),
        dof=put(prior.space.dof, None, empty.space.dof),
        scale=put(prior.space.scale, scale, empty.space.scale))
    new_prior = prior._replace(
        space=space,
        colour=prior.colour._replace(mean=put(prior.colour.mean, colour_ab, empty.colour.mean),
                                     kappa=put(prior.colour.kappa, None, empty.colour.kappa)),
        alpha=put(prior.alpha, None, empty.alpha))
    new_stats = merge_rows(stats, pairs)
    return state._replace(prior=new_prior, posterior=_m_step(new_prior, new_stats),
                          stats=new_stats)


def _merged_prior_rows(prior: Mixture, counts: np.ndarray, a: np.ndarray, b: np.ndarray):
    """The prior rows of components ``a [m]`` and ``b [m]`` merged into a's slot: the
    moment match of the two rows weighted by their counts (``counts [k]``), at a's
    strengths. Returns the mean ``[m, d]``, scale ``[m, d, d]`` and colour mean
    ``[m, 3]`` (float64); a's ``kappa``, ``dof``, colour ``kappa`` and ``alpha`` stay."""
    wa, wb = counts[a] + 1e-6, counts[b] + 1e-6
    ma, ca = _moments(prior.space, a)
    mb, cb = _moments(prior.space, b)
    m, c = _union(wa, ma, ca, wb, mb, cb)
    m, c = m.T, c.transpose(2, 0, 1)
    d = m.shape[-1]
    dof = np.asarray(prior.space.dof, np.float64)[a]
    colour = np.asarray(prior.colour.mean, np.float64)
    colour_ab = (wa[:, None] * colour[a] + wb[:, None] * colour[b]) / (wa + wb)[:, None]
    return m, c * (dof - d - 1.0)[:, None, None], colour_ab


def merge_rows(sums, pairs: np.ndarray):
    """Per-component sums (a NamedTuple of ``[k, ...]`` arrays or None, e.g.
    :class:`vbgs.inference.expfam.Stats`) with row ``b`` added to row ``a`` and zeroed,
    for each pair ``(a, b)`` of ``pairs [p, 2]`` (disjoint)."""
    a, b = pairs[:, 0], pairs[:, 1]

    def one(x):
        if x is None:
            return None
        out = np.array(x)
        out[a] = out[a] + out[b]
        out[b] = 0
        return jax.device_put(out)

    return type(sums)(*(one(x) for x in sums))


def component_evidence(prior: Mixture, posterior: Mixture, colour_noise: float):
    """``E_k`` ``[k]`` (module docstring): the log marginal likelihood of each component's
    points and colours, with its part of the mixing weights', ``posterior`` the
    conjugate update of ``prior`` on them."""
    counts = posterior.alpha - prior.alpha
    return (expfam.niw_log_evidence(prior.space, posterior.space)
            + expfam.colour_log_evidence(prior.colour, posterior.colour, colour_noise)
            + expfam.dirichlet_log_evidence_terms(prior.alpha, counts))


# compiled: once per capacity (every component) and per padded count of pairs
_evidence = jax.jit(component_evidence, static_argnames=("colour_noise",))


@partial(jax.jit, static_argnames=("colour_noise",))
def _merged_evidence(prior: Mixture, stats: expfam.Stats, colour_noise: float):
    return component_evidence(prior, m_step(prior, stats), colour_noise)


def _padded(rows: np.ndarray, size: int) -> np.ndarray:
    """``rows [m, ...]`` padded to ``size`` rows by repeating the first (results cut)."""
    return np.concatenate([rows, np.repeat(rows[:1], size - len(rows), 0)])


def merge_gains(state: State, pairs: np.ndarray, colour_noise: float) -> np.ndarray:
    """``[m]`` nats: the change of the bound (module docstring) if each pair of ``pairs
    [m, 2]`` alone were merged (a into a's slot, b's emptied)."""
    a, b = pairs[:, 0], pairs[:, 1]
    prior, stats = state.prior, state.stats
    dtype = np.dtype(prior.alpha.dtype)
    each = np.asarray(_evidence(prior, state.posterior, colour_noise), np.float64)
    counts = np.asarray(stats.count, np.float64)
    mean, scale, colour = _merged_prior_rows(prior, counts, a, b)
    size = 1 << max(10, (len(pairs) - 1).bit_length())  # a few sizes: few compilations

    def rows(field, merged=None):  # a's row (or the merged one), padded
        x = np.asarray(field)[a] if merged is None else merged.astype(dtype)
        return jax.device_put(_padded(x, size))

    merged_prior = Mixture(
        expfam.NIW(rows(prior.space.mean, mean), rows(prior.space.kappa),
                   rows(prior.space.dof), rows(prior.space.scale, scale)),
        expfam.ColourNormal(rows(prior.colour.mean, colour), rows(prior.colour.kappa)),
        rows(prior.alpha), prior.origin)
    summed = type(stats)(*(None if x is None else jax.device_put(_padded(
        np.asarray(x)[a] + np.asarray(x)[b], size)) for x in stats))
    joint = np.asarray(_merged_evidence(merged_prior, summed, colour_noise),
                       np.float64)[: len(pairs)]
    alpha0 = np.asarray(prior.alpha, np.float64)
    total, n = alpha0.sum(), counts.sum()
    return joint - each[a] - each[b] + alpha0[b] * (digamma(total + n) - digamma(total))


def bound_pairs(state: State, active: np.ndarray, colour_noise: float,
                neighbours: int = NEIGHBOURS) -> np.ndarray:
    """The disjoint pairs ``[p, 2]`` of neighbouring active components (``active [k]``)
    whose merge raises the bound (``gain > 0``, :func:`merge_gains`), best first."""
    pairs = neighbour_pairs(state.posterior, active, neighbours)
    if len(pairs) == 0:
        return pairs
    gain = merge_gains(state, pairs, colour_noise)
    better = np.flatnonzero(gain > 0)
    order = better[np.argsort(-gain[better], kind="stable")]
    return _disjoint(pairs, order, state.prior.n_components)
