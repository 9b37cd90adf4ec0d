"""The merge's candidate pairs and their costs, kept from one call to the next.

When the budget is spent, :func:`vbgs.inference.merge.choose_pairs` scores every pair of
neighbouring components: a KD-tree query of each active component's nearest and a cost
per pair. A stream whose slots are full does that nearly every frame (35 of the room's
60 at fit-scene's defaults), and it was most of growth's time there (70%). Between two
calls most components have not changed at all: a frame sees a part of the scene, and
60-77% of the room's components come out of it bit for bit the same. So
:func:`choose_pairs` keeps the last call's answer and redoes only what changed:

* a component's nearest are queried again where it moved (or became active), where one
  of them moved or left, or where a component that moved now lies within the distance
  of its farthest; elsewhere its nearest are the same points at the same distances;
* a pair's cost is computed again where either end changed (mean, covariance, colour or
  count); elsewhere it is the same row-wise arithmetic on the same numbers.

The answer is the from-scratch one (:func:`vbgs.inference.merge.choose_pairs`, the
reference): the queries run on a tree over the same means in the same order, and
``tests/vbgs/inference/test_kept_pairs.py`` holds the two together over a stream of
changes. One caveat, a tie: two components exactly as far from a third as its farthest
neighbour, where a tree over other points may list the other of the two.

What is kept is the last call's arrays, whatever map they came from: every call compares
all of them, so a call for another map redoes everything (the cost of no memory).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.inference import merge
from vbgs.inference.candidates import means_tree
from vbgs.inference.model import Mixture


class _Kept(NamedTuple):
    """One call's inputs (host copies) and answer."""

    mean: np.ndarray  # [k, d] posterior means
    scale: np.ndarray  # [k, d, d] posterior NIW scales
    dof: np.ndarray  # [k]
    colour: np.ndarray  # [k, 3] posterior colour means
    counts: np.ndarray  # [k]
    active: np.ndarray  # [k] bool
    near: np.ndarray  # [k, c] each active slot's nearest active slots (itself first)
    reach: np.ndarray  # [k] the distance to the farthest of them
    pairs: np.ndarray  # [p, 2] the neighbour pairs (slots, sorted)
    cost: np.ndarray  # [p] their costs
    settings: tuple  # (neighbours, colour_noise)


_last: list[_Kept | None] = [None]


def kept() -> _Kept | None:
    """What the last call kept, to :func:`put_back` after a call whose answer was dropped
    (a growth made again: :func:`vbgs.mapping.mapper.grow_components`), so the next call
    sees the history it would have seen without it."""
    return _last[0]


def put_back(last: _Kept | None) -> None:
    """Keep ``last`` (from :func:`kept`) as the last call's answer."""
    _last[0] = last


def choose_pairs(posterior: Mixture, counts: np.ndarray, active: np.ndarray, n: int,
                 colour_noise: float, neighbours: int = merge.NEIGHBOURS) -> np.ndarray:
    """:func:`vbgs.inference.merge.choose_pairs` (the same pairs), redoing only what
    changed since the last call (module docstring)."""
    if n <= 0:
        return np.zeros((0, 2), np.int64)
    pairs, cost = pairs_and_costs(posterior, counts, active, colour_noise, neighbours)
    return merge.cheapest_disjoint(pairs, cost, posterior.n_components, n)


def pairs_and_costs(posterior: Mixture, counts: np.ndarray, active: np.ndarray,
                    colour_noise: float, neighbours: int = merge.NEIGHBOURS
                    ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`vbgs.inference.merge.neighbour_pairs` ``[p, 2]`` and their
    :func:`vbgs.inference.merge.merge_costs` ``[p]``, from the last call's where the
    components are the same."""
    space = posterior.space
    now = dict(mean=np.array(space.mean), scale=np.array(space.scale),
               dof=np.array(space.dof), colour=np.array(posterior.colour.mean),
               counts=np.array(counts, np.float64), active=np.array(active, bool))
    idx = np.flatnonzero(now["active"])
    if len(idx) < 2:
        _last[0] = None
        return np.zeros((0, 2), np.int64), np.zeros(0)
    k, c = len(now["active"]), min(neighbours + 1, len(idx))
    settings = (neighbours, float(colour_noise))
    last = _last[0]
    if (last is None or last.settings != settings or last.near.shape[1] != c
            or last.mean.shape != now["mean"].shape):
        moved = changed = np.ones(k, bool)
        last = None
    else:
        moved = (now["active"] != last.active) | (now["mean"] != last.mean).any(1)
        changed = (moved | (now["scale"] != last.scale).any((1, 2)) | (now["dof"] != last.dof)
                   | (now["colour"] != last.colour).any(1) | (now["counts"] != last.counts))
    means = now["mean"][idx].astype(np.float64)
    near, reach = _nearest(means, idx, moved, last, c)
    pairs = merge.listed_pairs(idx, near[idx])
    cost = _costs(posterior, now["counts"], pairs, changed, last, k, colour_noise)
    _last[0] = _Kept(**now, near=near, reach=reach, pairs=pairs, cost=cost, settings=settings)
    return pairs, cost


def _nearest(means: np.ndarray, idx: np.ndarray, moved: np.ndarray, last: _Kept | None,
             c: int) -> tuple[np.ndarray, np.ndarray]:
    """``[k, c]`` each active slot's ``c`` nearest active slots (itself first, as the
    tree lists them) and ``[k]`` the distance to the farthest: queried again where the
    module docstring says, else the last call's (``means [a, d]`` of the active slots
    ``idx [a]``, ``moved [k]``)."""
    k = len(moved)
    near, reach = np.full((k, c), -1, np.int64), np.zeros(k)
    redo = np.ones(len(idx), bool)
    if last is not None:
        gone = np.append(moved, True)  # a neighbour -1 (none) reads the last: redone
        redo = moved[idx] | gone[last.near[idx]].any(1)
        went = idx[moved[idx]]  # components that moved (or arrived)
        still = np.flatnonzero(~redo)
        if len(went) and len(still):
            dist, _ = means_tree(means[moved[idx]]).query(means[still], k=1, workers=-1)
            redo[still[dist <= last.reach[idx[still]]]] = True
        keep = idx[~redo]
        near[keep], reach[keep] = last.near[keep], last.reach[keep]
    if redo.any():
        dist, pos = means_tree(means).query(means[redo], k=c, workers=-1)
        dist, pos = np.asarray(dist).reshape(-1, c), np.asarray(pos).reshape(-1, c)
        near[idx[redo]], reach[idx[redo]] = idx[pos], dist[:, -1]
    return near, reach


def _costs(posterior: Mixture, counts: np.ndarray, pairs: np.ndarray, changed: np.ndarray,
           last: _Kept | None, k: int, colour_noise: float) -> np.ndarray:
    """``[p]`` the merge costs of ``pairs``: the last call's where both ends are
    unchanged and the pair was scored then, else computed."""
    fresh = np.ones(len(pairs), bool)
    cost = np.empty(len(pairs))
    if last is not None and len(last.pairs):
        key = pairs[:, 0] * k + pairs[:, 1]
        last_key = last.pairs[:, 0] * k + last.pairs[:, 1]  # sorted
        at = np.minimum(np.searchsorted(last_key, key), len(last_key) - 1)
        fresh = (last_key[at] != key) | changed[pairs[:, 0]] | changed[pairs[:, 1]]
        cost[~fresh] = last.cost[at[~fresh]]
    if fresh.any():
        cost[fresh] = merge.merge_costs(posterior, counts, pairs[fresh], colour_noise)
    return cost
