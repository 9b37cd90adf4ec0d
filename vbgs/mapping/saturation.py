"""Points already explained are skipped: at most ``budget.saturation`` points learned per
cell of the map, decided before any expensive work.

A depth sensor's frame (640 x 480: 307k points) mostly shows ground the map has
already learned: under a stream of overlapping views, a component that has taken a
few dozen points of its surface hardly moves with more, yet every point costs its
candidate search, growth test and E-step. The map's growth rule already divides space
into cells (:mod:`vbgs.inference.grow`: level-0 cells of side ``cell``, far ground in
coarse cells of side ``cell 2^j``, ``j`` the point's :func:`vbgs.inference.grow.point_levels`),
about one component each. This module counts the points learned in each cell so far
(:class:`Seen`) and, for a new frame, keeps each point of a cell that holds ``c`` of
them, with ``m`` of the frame's points falling there, with probability

    p = clip((N - c) / m, 0, 1),       N = budget.saturation,

so a cell takes at most about ``N`` points over the whole stream (a cell seen first
takes ``N`` of its points, in expectation, spread at random over it), and a frame's
cost follows the ground it shows that the map has not yet learned: new ground is learned
as before, ground learned ``N`` times over costs only its unprojection and this test
(a few array passes over the frame's points on the host; no component is read).

What a skipped point would have added is a little more of the statistics of a
component already well determined (its mean, scatter and colour from ``N`` points of
its cell). Its ray still counts in the opacity evidence (read off the whole depth map,
:mod:`vbgs.render.opacity`), and a point of an empty cell is never skipped, so no new
ground is missed.

The counts live in a table of ``2^TABLE_BITS`` slots addressed by a hash of the cell
(level and integer coordinates). Each slot remembers the cell it counts; a cell whose
slot holds another cell counts as unseen (its points are kept, and the slot is handed
to it), so a collision costs time, never a skipped point of unseen ground.

The first frame is learned whole (the growth rule, and with it the cells, are fixed by
it); a frame whose every point is skipped still learns one (the step needs a batch).
The compiled step's padding then follows the batch (``Stepper(follow=True)``: one
compilation per octave of batch size, not one padded size that only grows).

``N`` is off by default (``N = 0`` keeps every point, bit for bit as before). The rule:
a limit is worth its place only where it is within 0.2 dB of every point on validation
views and saves time. On the room at 640 x 480 (``results/tuning/saturation/room640_16_64.*``
and ``room640_128_256.*``: 100k components, 18 frames, 2 validation views, every point
otherwise learned; each table names its command and code) the limits within 0.2 dB of
every point (``results/tuning/budget/room640_points_5k_40k.md``) are 128 and 256, and
128 skipped 17% of the points for about no CPU saved (1.22 against 1.29 s a frame, at an
earlier code); the point budget of 80000 (stride 2, :mod:`vbgs.mapping.budget`) is within
it at 0.47 s then. 128 px frames give a cell few points a frame: there N = 32 skipped
32% of the object's points for no time saved (each new octave of batch size compiles)
and cost 0.37 dB (an earlier code's one-off run). ``--budget-saturation N`` asks for it on a
sensor's frames.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np

from vbgs.inference import grow

# 2^21 slots (16 MiB of cell keys, 8 MiB of counts): ten times the cells of a 100k
# component map, so few collisions (each only costs time).
TABLE_BITS = 21
# Cell coordinates are packed into 20 bits each (±2^19 cells about the grid's origin:
# kilometres at centimetre cells); the level goes in the bits above them.
_COORD_BITS = 20
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing's multiplier (2^64 / phi)


class Seen(NamedTuple):
    """Points learned per cell: ``cell [T]`` int64 the cell key each slot counts (-1:
    none), ``count [T]`` int32 its points. Host arrays, replaced (never changed in place)
    frame by frame."""

    cell: np.ndarray
    count: np.ndarray


def nothing_seen(bits: int = TABLE_BITS) -> Seen:
    """A table of ``2^bits`` slots with no cell counted."""
    return Seen(np.full(1 << bits, -1, np.int64), np.zeros(1 << bits, np.int32))


def cell_keys(rule: grow.Growth, xyz, origin, levels=None) -> np.ndarray:
    """``[n]`` int64: the cell of each point ``xyz [n, 3]`` (world), the level-0 cell of
    side ``rule.cell`` about ``origin [3]``, or with ``levels [n]`` its coarse cell of
    side ``rule.cell 2^level`` (:func:`vbgs.inference.grow.point_levels`)."""
    x = np.asarray(xyz, np.float64) - np.asarray(origin, np.float64)
    level = np.zeros(len(x), np.int64) if levels is None else np.asarray(levels, np.int64)
    side = rule.cell * np.exp2(level)[:, None]
    ijk = grow.cell_index(x / side, 1.0) & ((1 << _COORD_BITS) - 1)  # two's complement wrap
    key = level
    for j in range(ijk.shape[1]):  # the level, then one field per axis
        key = key << _COORD_BITS | ijk[:, j]
    return key


def _slots(keys: np.ndarray, bits: int) -> np.ndarray:
    """``[n]`` the table slot of each cell key (Fibonacci hashing: the top ``bits`` bits
    of the key times the golden multiplier, mod 2^64)."""
    return (keys.astype(np.uint64) * _GOLDEN >> np.uint64(64 - bits)).astype(np.int64)


def keep(seen: Seen, keys: np.ndarray, cap: int, *, key: jax.Array) -> np.ndarray:
    """``[n]`` bool: the points (cells ``keys [n]``) a frame learns under the cap ``N =
    cap`` (module docstring: a point of a cell with ``c`` points learned and ``m`` in
    this frame is kept with probability ``clip((N - c) / m, 0, 1)``, drawn under
    ``key``)."""
    bits = int(np.log2(len(seen.count)))
    slot = _slots(keys, bits)
    known = seen.cell[slot] == keys
    before = np.where(known, seen.count[slot], 0)
    in_frame = np.bincount(slot, minlength=len(seen.count))[slot]  # m (by slot: a clash
    #                                    of two of the frame's cells lowers both p a little)
    p = np.clip((cap - before) / in_frame, 0.0, 1.0)
    return grow.host_rng(key).random(len(keys)) < p


def add(seen: Seen, keys: np.ndarray) -> Seen:
    """``seen`` with the learned points of cells ``keys [n]`` counted; a slot that held
    another cell is handed to the new one (its count restarts)."""
    cell, slot, fresh, mine = claim(seen.cell, keys)
    count = seen.count.copy()
    count[fresh] = 0
    count += np.bincount(slot[mine], minlength=len(count)).astype(np.int32)
    return Seen(cell, count)


def claim(cells: np.ndarray, keys: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The slots of cells ``keys [n]`` in a table whose slots hold the cells ``cells [T]``
    (-1: none; ``T`` a power of two): the table's cells with a slot that held another
    cell handed to the new one (of clashing new cells in one slot, the last wins), each
    key's slot ``[n]``, the slots handed over (their sums restart) and ``[n]`` bool: the
    keys that hold their slot."""
    slot = _slots(keys, int(np.log2(len(cells))))
    cell = cells.copy()
    other = cell[slot] != keys
    cell[slot[other]] = keys[other]
    return cell, slot, slot[other], cell[slot] == keys
