"""The prior's length scale from the cells the data occupy, whatever their dimension.

Depth points lie on 2-D surfaces inside a 3-D box. If K components tiled the box, each
would own a cell of side ``(V / K)^(1/3)`` (:func:`vbgs.inference.model.cell_length`); but the
data fill only a thin shell of the box, so that cell is far larger than the spacing
of K components spread over the surface, about ``sqrt(A / K)`` for a surface of area
A, and the prior blurs more as K grows. Here the length scale is the side ``ell`` of
the grid cells at which the data occupy K cells:

    ell = max { h : N_occ(h) >= K },   N_occ(h) = #{ floor((x_n - lo) / h) : n }   (distinct)

For data filling a d-dimensional region of measure M, ``N_occ(h) ≈ c M / h^d``, so
``ell ≈ (c M / K)^(1/d)`` follows the data's own dimension with no dimension given:
a surface of area A gives ``ell ≈ sqrt(c A / K)`` with ``c = |n_x| + |n_y| + |n_z|``
for its normal n (the cubes a plane crosses per unit area; 1 for an axis-aligned plane,
1.5 averaged over orientations, at most sqrt 3), and data filling the box give the box
cell. Why occupancy and not the area seen by the cameras (each pixel covers
``z^2 / (f_x f_y)`` at its depth): views of a stream overlap, an orbit sees every
surface from tens of frames, and summing per-frame areas counts it that many times;
occupied cells count each piece of surface once however often it was seen, need no
cameras, and do not depend on the order the points arrived in.

Only the points handed to the prior are used (for a stream: what has arrived). With
fewer distinct points than K the target is their number (``ell`` then about their
spacing). The result never exceeds ``upper`` (the box cell), so data that fill their
box, such as an image's pixel grid, keep the box cell exactly.
"""

from __future__ import annotations

import numpy as np

BISECTION_STEPS = 14  # halvings of log(MAX_SHRINK) = 9.2: ell to within 0.06%
MAX_SHRINK = 1e4  # ell is searched in [upper / MAX_SHRINK, upper]


def occupied_cells(xyz: np.ndarray, lo: np.ndarray, h: float) -> int:
    """``N_occ(h)``: distinct cells of the grid of side ``h`` anchored at ``lo [d]`` that
    hold at least one of the points ``xyz [n, d]``."""
    cells = np.floor((xyz - lo) / h).astype(np.int64)  # [n, d]
    cells -= cells.min(0)
    sizes = cells.max(0) + 1  # [d] cells per axis
    if np.prod(sizes.astype(np.float64)) < 2.0**62:  # one int64 key per cell: a fast 1-D unique
        keys = np.ravel_multi_index(tuple(cells.T), tuple(int(s) for s in sizes))  # [n]
        return int(np.unique(keys).shape[0])
    return int(np.unique(cells, axis=0).shape[0])


def occupied_cell_length(xyz, n_components: int, lo, upper: float) -> float:
    """``ell = max {h <= upper : N_occ(h) >= min(K, distinct points)}`` (see the module
    docstring), by bisection on ``log h`` over ``[upper / MAX_SHRINK, upper]``.

    xyz: ``[n, d]`` points; lo: ``[d]`` grid anchor (the data's box corner); upper: the
    box cell length, returned unchanged when the data already occupy K cells at it.
    """
    pts = np.asarray(xyz, np.float64)  # [n, d]
    lo = np.asarray(lo, np.float64)  # [d]
    if pts.ndim != 2 or pts.shape[0] == 0:
        raise ValueError(f"occupied_cell_length needs points [n, d] with n >= 1, got {pts.shape}")
    if not (upper > 0 and np.isfinite(upper)):
        raise ValueError(f"upper must be a positive finite length, got {upper}")
    target = min(int(n_components), occupied_cells(pts, lo, upper / MAX_SHRINK))
    if occupied_cells(pts, lo, upper) >= target:
        return float(upper)
    small, big = np.log(upper / MAX_SHRINK), np.log(upper)  # N_occ(e^small) >= target
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (small + big)
        if occupied_cells(pts, lo, float(np.exp(mid))) >= target:
            small = mid
        else:
            big = mid
    return float(np.exp(small))
