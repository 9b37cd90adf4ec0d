"""Cells of the growth grid (vbgs.inference.cells): keys equal exactly where the cells are,
and the table and the binary search give the same answer as a set of cell tuples."""

import numpy as np
import pytest

from vbgs.inference import cells


def _groups(rng, cell_scale: float = 1.0):
    taken = rng.uniform(-3.0, 3.0, (400, 3)) * cell_scale
    points = [rng.uniform(-2.0, 2.0, (3000, 3)) * cell_scale for _ in range(3)]
    return taken, points


def _set_answer(taken, points, cell):
    held = {tuple(c) for c in cells.cell_index(taken, cell)}
    return np.array([[tuple(c) in held for c in cells.cell_index(p, cell)] for p in points])


@pytest.mark.parametrize("dense_cells", [0, 1 << 26])  # the binary search, the table
def test_held_is_the_set_of_cells_that_hold_a_component(monkeypatch, dense_cells):
    monkeypatch.setattr(cells, "DENSE_CELLS", dense_cells)
    rng = np.random.default_rng(0)
    taken, points = _groups(rng)
    (taken_keys, *point_keys), size = cells.box_keys([taken, *points], 0.5)
    got = cells.held(taken_keys, np.stack(point_keys), size)
    want = _set_answer(taken, points, 0.5)
    assert 0.05 < want.mean() < 0.95 and np.array_equal(got, want)


def test_box_keys_equal_exactly_where_the_cells_are():
    rng = np.random.default_rng(1)
    taken, points = _groups(rng)
    (taken_keys, *point_keys), size = cells.box_keys([taken, *points], 0.25)
    every = np.concatenate([taken, *points])
    keys = np.concatenate([taken_keys, *point_keys])
    rows = cells.cell_index(every, 0.25)
    assert keys.min() >= 0 and keys.max() < size
    labels = np.unique(rows, axis=0, return_inverse=True)[1].reshape(-1)
    assert len(set(zip(keys, labels, strict=True))) == len(set(keys)) == len(set(labels))


def test_a_box_too_wide_to_pack_labels_the_distinct_cells():
    rng = np.random.default_rng(2)
    taken, points = _groups(rng)
    wide = [g * np.array([2.0**40, 2.0**30, 1.0]) for g in (taken, *points)]
    (taken_keys, *point_keys), size = cells.box_keys(wide, 0.5)
    assert size <= sum(len(g) for g in wide)  # labels, not a packed box
    got = cells.held(taken_keys, np.stack(point_keys), size)
    assert np.array_equal(got, _set_answer(wide[0], wide[1:], 0.5))


def test_no_component_holds_nothing():
    rng = np.random.default_rng(3)
    _, points = _groups(rng)
    (taken_keys, *point_keys), size = cells.box_keys([np.zeros((0, 3)), *points], 0.5)
    assert not cells.held(taken_keys, np.stack(point_keys), size).any()
