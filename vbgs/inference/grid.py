"""Candidate search on the device: per-cell candidate lists on a uniform grid.

Each point's candidates are its ``C`` Euclidean-nearest component means, exactly as
the KD-tree of :mod:`vbgs.inference.candidates` gives them (up to distance ties), found per
frame with JAX ops only (no host round trip):

1. **plan and build** (host, once per assigning model; under prior assignment once
   per stream): space is cut into cubic cells of side ``h``; each cell near the means
   stores every mean that can be among the ``C`` nearest of any point in the cell
   (a provable superset, :func:`build`), padded to a fixed length ``L``;
2. **search** (device, every frame): a point looks up its cell's list (one contiguous
   gather), keeps the ``C`` nearest of those ``L`` (``top_k``); points outside the
   listed cells (rare) are searched exhaustively in fixed-size batches.

Distances are elementwise sums of squared centred differences: no matrix products,
exact under TF32.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# Cell side as a fraction of the median distance from a mean to its C-th nearest mean.
CELL_FRACTION = 0.7
# Candidate lists longer than this quantile of the list lengths are not stored: their
# cells' points take the exhaustive fallback.
LIST_QUANTILE = 0.99
# Each cell's list is found among its centre's LIST_SEARCH_FACTOR x C nearest means.
LIST_SEARCH_FACTOR = 16
# Cells whose lists are built together (bounds the build's memory).
BUILD_BLOCK = 4096
# search="auto" uses the grid only when building it costs at most this many distances
# (beyond, e.g. 100k components spread through a room's volume, the build takes minutes
# and gigabytes on the host and the KD-tree is the better choice).
MAX_BUILD_COST = 1 << 24
# Cells in the grid at most (the cell table is one int32 per cell).
MAX_CELLS = 1 << 24


class GridSpec(NamedTuple):
    """Static (hashable) layout of the grid, in the model's centred frame."""

    lo: tuple[float, ...]  # [d] corner of cell 0
    cell: float  # h, the cell side
    dims: tuple[int, ...]  # [d] cells per axis
    n_candidates: int  # C

    @property
    def n_cells(self) -> int:
        return math.prod(self.dims)


class CellLists(NamedTuple):
    """For each listed cell, every component that can be among the C nearest of a point
    in the cell (a provable superset, see :func:`build`).

    row ``[G]``: the cell's row in the tables, -1 where the cell has no stored list;
    ids ``[R, L]``: component indices (padded with 0); means ``[R, d, L]``: their means,
    coordinates first for vectorised distances (padded with +inf: never nearest).
    """

    row: jnp.ndarray  # [G] int32
    ids: jnp.ndarray  # [R, L] int32
    means: jnp.ndarray  # [R, d, L]


def plan(means, n_candidates: int) -> GridSpec:
    """Cell side ``h = CELL_FRACTION x median r_C`` (``r_C``: a mean's distance to its
    C-th nearest other mean) and a box covering the means with one spare cell a side."""
    means = np.asarray(means, np.float64)
    k, d = means.shape
    n_cand = int(min(n_candidates, k))
    if n_cand < 1:
        raise ValueError(f"n_candidates must be at least 1, got {n_candidates}")
    from scipy.spatial import cKDTree  # imported when used: 0.2-0.4 s at start-up

    r_c = cKDTree(means).query(means, k=min(n_cand + 1, k))[0].reshape(k, -1)[:, -1]
    extent = means.max(0) - means.min(0)
    cell = max(float(np.median(r_c)) * CELL_FRACTION, 1e-6 * max(float(extent.max()), 1e-30))
    while math.prod(int(e // cell) + 3 for e in extent) > MAX_CELLS:
        cell *= 1.25
    lo = means.min(0) - cell
    return GridSpec(tuple(float(v) for v in lo), cell, tuple(int(e // cell) + 3 for e in extent),
                    n_cand)


def _cell_coords(x: np.ndarray, spec: GridSpec) -> np.ndarray:
    return np.floor((x - np.asarray(spec.lo)) / spec.cell).astype(np.int64)


def build(means, spec: GridSpec) -> CellLists:
    """Candidate lists for the cells holding a mean and their neighbours (host, once per
    assigning model).

    Let ``U`` be the C-th smallest, over the means, of the largest distance from a mean
    to the cell's box. Any point x of the box has at least C means within ``U``, so a
    mean can be among the C nearest of x only if its smallest distance to the box is at
    most ``U``: the list is every such mean (a superset of the C nearest of every point
    of the cell). One KD-tree query of the ``LIST_SEARCH_FACTOR x C`` means nearest the
    cell's centre finds them; cells where that query may miss some (or whose list is
    longer than the :data:`LIST_QUANTILE` quantile of the lengths) get no list and their
    points take the exhaustive fallback.
    """
    means = np.asarray(means, np.float64)
    k, d = means.shape
    cells = listed_cells(means, spec)
    search = min(k, LIST_SEARCH_FACTOR * spec.n_candidates)
    from scipy.spatial import cKDTree

    tree = cKDTree(means)
    ids = np.zeros((len(cells), search), np.int32)  # live entries first
    sizes, complete = np.zeros(len(cells), np.int64), np.zeros(len(cells), bool)
    for lo in range(0, len(cells), BUILD_BLOCK):  # blocks bound the float64 temporaries
        block = slice(lo, lo + BUILD_BLOCK)
        centres = _centres(cells[block], spec)
        dist, near = tree.query(centres, k=search, workers=-1)
        dist, near = dist.reshape(len(centres), search), near.reshape(len(centres), search)
        # distances from each found mean to the nearest and farthest point of the cell box
        gap = np.abs(means[near] - centres[:, None, :])  # [block, search, d]
        half = 0.5 * spec.cell
        mindist = np.sqrt((np.maximum(gap - half, 0.0) ** 2).sum(-1))
        maxdist = np.sqrt(((gap + half) ** 2).sum(-1))
        bound = np.partition(maxdist, spec.n_candidates - 1, axis=1)[:, spec.n_candidates - 1]
        live = mindist <= bound[:, None]  # can be among the C nearest of a point of the cell
        sizes[block] = live.sum(1)
        # means not found are at least dist[:, -1] from the centre, so at least that minus
        # the half-diagonal from the box: the list is complete if that exceeds the bound
        complete[block] = (dist[:, -1] - math.sqrt(d) * half > bound) | (search == k)
        rank = np.argsort(~live, axis=1, kind="stable")  # live first, nearest first
        ids[block] = np.take_along_axis(near, rank, 1)
    length = max(spec.n_candidates, int(np.quantile(sizes[complete], LIST_QUANTILE))
                 if complete.any() else spec.n_candidates)
    keep = complete & (sizes <= length)
    row = np.full(spec.n_cells, -1, np.int32)
    row[cells[keep]] = np.arange(keep.sum(), dtype=np.int32)
    live = np.arange(length)[None] < sizes[keep][:, None]
    ids = np.where(live, ids[keep, :length], 0)
    tab = np.where(live[..., None], means[ids].astype(np.float32), np.inf)  # [R, L, d]
    return CellLists(jnp.asarray(row), jnp.asarray(ids, jnp.int32),
                     jnp.asarray(tab.transpose(0, 2, 1)))


def listed_cells(means, spec: GridSpec) -> np.ndarray:
    """Flat indices of the cells that get a list: those holding a mean and their
    neighbours (the box has a spare cell a side, so no neighbour wraps around)."""
    means = np.asarray(means, np.float64)
    d = means.shape[1]
    occupied = np.zeros(spec.dims, bool)
    occupied[tuple(np.clip(_cell_coords(means, spec), 0, np.asarray(spec.dims) - 1).T)] = True
    near = occupied.copy()
    for off in itertools.product((-1, 0, 1), repeat=d):
        near |= np.roll(occupied, off, axis=tuple(range(d)))
    return np.flatnonzero(near)


def build_cost(means, spec: GridSpec) -> int:
    """Distances :func:`build` evaluates (listed cells x means searched per cell)."""
    k = np.shape(means)[0]
    return len(listed_cells(means, spec)) * min(k, LIST_SEARCH_FACTOR * spec.n_candidates)


def _centres(cells: np.ndarray, spec: GridSpec) -> np.ndarray:
    return np.asarray(spec.lo) + (np.stack(np.unravel_index(cells, spec.dims), -1) + 0.5) \
        * spec.cell


def exhaustive(means: jnp.ndarray, x: jnp.ndarray, n_candidates: int) -> jnp.ndarray:
    """The ``C`` nearest means ``[k, d]`` to each point ``x [m, d]`` by brute force,
    ``[m, C]`` (the slow reference and the fallback)."""
    diff = x[:, None, :] - means[None]  # [m, k, d]
    return jax.lax.top_k(-jnp.sum(diff * diff, -1), n_candidates)[1].astype(jnp.int32)


def search(lists: CellLists, means: jnp.ndarray, x: jnp.ndarray, w: jnp.ndarray,
           spec: GridSpec) -> jnp.ndarray:
    """The ``C`` nearest component means ``[k, d]`` to each point ``x [n, d]``, ``[n, C]``
    int32, with JAX ops only (jittable; ``spec`` static).

    A point in a listed cell takes the C nearest of its cell's list (exact: the list is a
    superset); a point outside the box or in an unlisted cell is searched exhaustively,
    in fixed batches inside a ``while_loop``. Points with weight ``w = 0`` (padding)
    get candidates from a neighbouring list or zeros, never the fallback.
    """
    n, d = x.shape
    dims = jnp.asarray(spec.dims, jnp.int32)
    ci = jnp.floor((x - jnp.asarray(spec.lo, x.dtype)) / spec.cell).astype(jnp.int32)
    inside = jnp.all((ci >= 0) & (ci < dims), -1)  # [n]
    ci = jnp.clip(ci, 0, dims - 1)
    key = ci[:, 0]
    for axis in range(1, d):
        key = key * spec.dims[axis] + ci[:, axis]
    row = jnp.where(inside, lists.row[key], -1)  # [n]
    safe = jnp.maximum(row, 0)
    diff = x[:, :, None] - lists.means[safe]  # [n, d, L]
    pos = jax.lax.top_k(-jnp.sum(diff * diff, 1), spec.n_candidates)[1]  # [n, C]
    cand = jnp.take_along_axis(lists.ids[safe], pos, 1)
    todo = (row < 0) & (w > 0)
    batch = max(1, min(32, (1 << 20) // max(means.shape[0], 1)))

    def body(carry):
        cand, todo = carry
        idx = jnp.nonzero(todo, size=batch, fill_value=n)[0]  # [B]; n marks "none"
        near = exhaustive(means, x[jnp.minimum(idx, n - 1)], spec.n_candidates)
        return cand.at[idx].set(near, mode="drop"), todo.at[idx].set(False, mode="drop")

    cand, _ = jax.lax.while_loop(lambda c: jnp.any(c[1]), body, (cand, todo))
    return cand
