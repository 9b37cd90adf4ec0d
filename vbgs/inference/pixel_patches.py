"""A frame's points' neighbours found on its pixel grid, not in a KD-tree.

A frame's points come from a depth image, so the points nearest a point in 3-D are,
on one surface, those of the pixels about its own pixel. Growth fits each seed's patch
(:mod:`vbgs.inference.quadric`) to such neighbours; a KD-tree over the frame's points
(:func:`vbgs.inference.quadric.neighbour_index`, the reference, which bare point batches
still take) finds them by building a tree of all ~300k points of a 640 x 480 frame for a
few thousand queries. Here they are read off an index image instead: ``[h, w]`` of point
indices, -1 where the pixel has no point, gathered at once for all seeds (``[m, k]``).

The window is the smallest disc of pixel offsets that holds :data:`WINDOW_SHARE` times
the wanted count (:func:`disc`): 48 neighbours look in the 121 pixels within 6.1 pixels,
12 in the 37 within 3.2; of its points that pass the rule below, the wanted nearest in
3-D are taken, as the KD-tree takes them. Why not the window that holds just the wanted
count (49 pixels within 4 for 48): under a sensor's noise the 48 nearest points in 3-D
spread wider than 4 pixels (a point's neighbours along its ray are far in depth), and
their wider patch tells the normal better. Against the normals and points of the exact
depth (a one-off check: three object frames at 128 px under the Kinect's simulated
noise, 2000 seeds each), the KD-tree's normals were 4.26 degrees off (median; mean
6.97), the 49-pixel window's 5.69 (9.05), the nearest 48 of 121 pixels 4.26 (6.99);
the seeds of the last 0.21 sigma off the surface (median) as the KD-tree's, the
49-pixel window's 0.24. Within 2 or 1.6 times the wanted count the normals were 7.07
and 7.20 degrees off (mean). On a thinned frame (``budget.points``: every s-th pixel) the
offsets step by ``s``.

A window's pixel takes no part when it has no point, or when its point lies farther from
the seed in 3-D than the surface it would share with it allows: a window straddling a
depth edge would mix a foreground and a background surface. The rule: a neighbour ``j``
at pixel offset ``d_j`` (in pixels) is kept when

    |x_j - x_s|^2 <= (FOOTPRINTS * f_s * s * |d_j|)^2 + 2 NOISE_SIGMAS^2 |u_s|^2,

``f_s`` the seed's pixel footprint (depth / focal length, world units), ``u_s`` its
noise along its ray (0 for exact depth; a neighbour's, about as deep, is taken to be
the same). On a surface tilted by ``theta`` from the view a neighbour lies about
``f_s |d_j| / cos(theta)`` away, so :data:`FOOTPRINTS` = 3 keeps surfaces up to 70
degrees from head-on whole; a step in depth of more than some
``3 f_s |d_j|`` (and a few sigma of the noise) is cut. What is left is a masked patch
(``weight [m, k]``, 0 or 1), which the quadric code fits as it fits the KD-tree's (all
weights 1). A window of fewer than ``quadric.PLANE_MIN_POINTS`` kept points (the seed
alone on its surface: a speck, a thin rim) tells no plane: its seed stays at its
measured point with a normal along its viewing ray (:func:`view_normals`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# A neighbour lies on the seed's surface when it is within this many of the seed's pixel
# footprints per pixel of offset (a surface up to arccos(1/3) = 70 degrees from head-on).
FOOTPRINTS = 3.0
# ... plus this many sigma of the two points' noise along their rays (each the seed's).
NOISE_SIGMAS = 3.0
# The window holds this many times the wanted neighbours, the nearest of which in 3-D
# are taken (module docstring: 1, the window of the wanted count, loses to the KD-tree).
WINDOW_SHARE = 2.5


class PixelGrid(NamedTuple):
    """Where a frame's points lie on its pixel grid (what :func:`window` reads)."""

    flat: np.ndarray  # [n] int: each point's pixel, row * width + col
    shape: tuple[int, int]  # (height, width) of the image
    step: int  # the lattice the points' pixels lie on (a thinned frame's stride; 1: all)
    footprint: np.ndarray  # [n] each point's pixel footprint (depth / focal, world units)
    eye: np.ndarray  # [3] the camera centre, in the points' coordinates


def disc(wanted: int) -> np.ndarray:
    """``[k, 2]`` int (row, col) offsets: the smallest disc of pixel offsets that holds at
    least ``wanted`` pixels (offset 0 among them), nearest first."""
    r = int(np.ceil(np.sqrt(wanted)))
    span = np.arange(-r, r + 1)
    off = np.stack(np.meshgrid(span, span, indexing="ij"), -1).reshape(-1, 2)
    d2 = (off**2).sum(1)
    order = np.argsort(d2, kind="stable")
    cut = d2[order][min(wanted, len(order)) - 1]  # the wanted-th nearest's distance
    return off[order][d2[order] <= cut]


def index_image(grid: PixelGrid, pad: int) -> np.ndarray:
    """``[h + 2 pad, w + 2 pad]`` int: each pixel's point (-1: none), padded by ``pad``
    pixels of -1 so every window reads inside it."""
    h, w = grid.shape
    image = np.full((h + 2 * pad, w + 2 * pad), -1, np.int64)
    image[grid.flat // w + pad, grid.flat % w + pad] = np.arange(len(grid.flat))
    return image


def window(x: np.ndarray, chosen: np.ndarray, grid: PixelGrid, wanted: int,
           ray: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The patches of the points ``x[chosen]`` of ``x [n, 3]`` on the pixel grid: their
    indices ``[m, k]`` into ``x`` (a masked slot holds the point itself) and weights
    ``[m, k]`` (1: a point of the seed's surface; 0: no point, or one beyond the radius
    of the module docstring), ``k = wanted`` nearest in 3-D of a disc of
    :data:`WINDOW_SHARE` times as many pixels. ``ray [n, 3]``: the points' noise along
    their rays."""
    off = disc(max(wanted, int(np.ceil(WINDOW_SHARE * wanted))))  # [k, 2]
    pad = grid.step * int(np.abs(off).max())
    image = index_image(grid, pad)
    width = image.shape[1]
    row, col = np.divmod(grid.flat[chosen], grid.shape[1])  # [m] the seeds' pixels
    at = (row + pad) * width + col + pad  # ... in the padded image, flat
    idx = image.ravel()[at[:, None] + grid.step * (off[:, 0] * width + off[:, 1])]  # [m, k]
    valid = idx >= 0
    idx = np.where(valid, idx, chosen[:, None])
    x = np.asarray(x, np.float32)  # distances to choose by: float32 halves the traffic
    dist = np.zeros(idx.shape, np.float32)  # [m, k] squared, a coordinate at a time (a
    for axis in range(x.shape[1]):  # third as long as the gap of [m, k, 3] in one)
        column = np.ascontiguousarray(x[:, axis])
        gap = column[idx] - column[chosen][:, None]
        dist += gap * gap
    fp = np.asarray(grid.footprint, np.float64)[chosen][:, None]  # [m, 1]
    reach = (FOOTPRINTS * grid.step * fp)**2 * (off**2).sum(1)  # [m, k]
    if ray is not None:  # the seed's noise stands for its neighbour's (about as deep)
        reach = reach + 2.0 * NOISE_SIGMAS**2 * (np.asarray(ray, np.float64)[chosen]**2
                                                 ).sum(1)[:, None]
    keep = valid & (dist <= reach)
    if wanted < len(off):  # the wanted nearest of the kept (the masked ones last)
        near = np.argpartition(np.where(keep, dist, np.inf), wanted - 1, axis=1)[:, :wanted]
        idx, keep = np.take_along_axis(idx, near, 1), np.take_along_axis(keep, near, 1)
    return np.where(keep, idx, chosen[:, None]), keep.astype(np.float64)


def view_normals(x: np.ndarray, chosen: np.ndarray, grid: PixelGrid) -> np.ndarray:
    """``[m, 3]`` unit: the viewing rays of the points ``x[chosen]`` (from the camera
    centre), the normal a seed takes whose window tells no plane."""
    d = np.asarray(x, np.float64)[chosen] - np.asarray(grid.eye, np.float64)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
