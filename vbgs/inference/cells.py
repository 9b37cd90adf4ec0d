"""Cells of the growth grid: which points lie in a cell that holds a component.

Growth (:mod:`vbgs.inference.grow`) cuts space into cubes (squares in 2-D) of side
``cell`` and asks, for every point of a frame, whether a component's mean lies in the
point's cell (and, for measured points, in the cells a step of noise before and behind
it). At sensor size that is a million cell lookups a frame against a hundred thousand
components, so the lookup is arranged for numpy:

* a cell is the integer floor of a position over the side (:func:`cell_index`);
* the cells of one lookup, the components' and the points', are packed into one int64
  each by their place in the box that holds them all (:func:`box_keys`: two cells get
  the same key exactly when they are the same cell);
* when that box has at most :data:`DENSE_CELLS` cells (and not many more than the keys
  looked up), a table of one bool per cell
  answers every point with one gather (:func:`held`); otherwise the components' keys
  are sorted and each point's key found by binary search, which costs about five times
  more (0.15 s against 0.03 s for 800k points at 64M cells on this project's 2-core
  CPU). Both give the same answer; ``tests/vbgs/inference/test_cells.py`` holds them
  to a set of cell tuples.

The box is read from the positions before the floor (``floor(min x / c)`` is the
smallest cell: division by a positive side and the floor are both monotone), one
contiguous column at a time: a reduction over the rows of an ``[n, 3]`` int64 array
took three times as long.
"""

from __future__ import annotations

import numpy as np

# The most cells a box may hold for the one-bool-per-cell table (64 MB), and the most per
# key looked up (a table is zeroed cell by cell, about 1 ns each; a binary search costs
# 30-150 ns a key): a larger box (fine refinement cells over a whole room, or a few
# points in a wide box) takes the sorted keys and a binary search.
DENSE_CELLS = 1 << 26
DENSE_CELLS_PER_KEY = 32


def cell_index(x: np.ndarray, cell: float) -> np.ndarray:
    """Integer cell coordinates ``[n, d]`` of centred positions ``x [n, d]``."""
    return np.floor(np.asarray(x, np.float64) / cell).astype(np.int64)


def cell_keys(cells: np.ndarray) -> np.ndarray:
    """``[n]`` int64 keys of the rows of integer cell coordinates ``cells [n, d]``, equal
    exactly where the rows are: the rows packed into one int64 each when their box allows
    (a 1-D sort is far faster than one over rows), else labels of the distinct rows."""
    lo = cells.min(0)
    span = cells.max(0) - lo + 1
    if np.prod(span.astype(np.float64)) >= 2.0**62:  # too wide to pack: unique over rows
        return np.unique(cells, axis=0, return_inverse=True)[1].reshape(-1)
    return _packed(cells, lo, span)


def _packed(cells: np.ndarray, lo: np.ndarray, span: np.ndarray) -> np.ndarray:
    """``[n]``: the rows ``cells [n, d]`` packed in C order in the box from ``lo [d]`` of
    ``span [d]`` cells a side (``np.ravel_multi_index``)."""
    key = cells[:, 0] - lo[0]
    for j in range(1, cells.shape[1]):
        key = key * span[j] + (cells[:, j] - lo[j])
    return key


def _box(groups: list[np.ndarray], cell: float) -> tuple[np.ndarray, np.ndarray]:
    """The smallest and largest cell ``[d]`` of the positions of all ``groups`` (each
    ``[n_i, d]``, float64; empty ones skipped), from each column's extremes."""
    full = [g for g in groups if len(g)]
    d = full[0].shape[1]
    lo = np.array([min(g[:, j].min() for g in full) for j in range(d)])
    hi = np.array([max(g[:, j].max() for g in full) for j in range(d)])
    return np.floor(lo / cell).astype(np.int64), np.floor(hi / cell).astype(np.int64)


def box_keys(groups: list[np.ndarray], cell: float) -> tuple[list[np.ndarray], int]:
    """The cells of side ``cell`` of the positions in ``groups`` (each ``[n_i, d]``
    float64, at least one not empty) as keys ``[n_i]`` in ``[0, size)``, equal exactly
    where the cells are, and ``size``: the keys packed in the box that holds them all,
    of ``size`` cells; when that box is too large to pack into an int64, labels of the
    distinct cells (:func:`cell_keys`)."""
    lo, hi = _box(groups, cell)
    span = hi - lo + 1
    size = float(np.prod(span.astype(np.float64)))
    if size < 2.0**62:
        return [_packed(cell_index(g, cell), lo, span) for g in groups], int(size)
    keys = cell_keys(cell_index(np.concatenate(groups), cell))
    ends = np.cumsum([len(g) for g in groups])[:-1]
    return np.split(keys, ends), int(keys.max()) + 1


def held(taken_keys: np.ndarray, keys: np.ndarray, size: int) -> np.ndarray:
    """``keys.shape`` bool: which of the packed ``keys`` (any shape) are among
    ``taken_keys [m]``, all in ``[0, size)`` (:func:`box_keys`): a table of one bool per
    cell when the box is small enough (:data:`DENSE_CELLS`, :data:`DENSE_CELLS_PER_KEY`),
    else a binary search in the sorted ``taken_keys``."""
    if len(taken_keys) == 0:
        return np.zeros(keys.shape, bool)
    if size <= min(DENSE_CELLS, DENSE_CELLS_PER_KEY * keys.size):
        table = np.zeros(size, bool)
        table[taken_keys] = True
        return table[keys]
    sorted_keys = np.sort(taken_keys)
    at = np.minimum(np.searchsorted(sorted_keys, keys), len(sorted_keys) - 1)
    return sorted_keys[at] == keys
