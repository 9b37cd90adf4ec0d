"""A frame's point budget: at most ``budget.points`` points learned per frame, chosen
before any expensive work.

A depth sensor's frame (640 x 480: 307k points) carries far more points than a map's
components need once a surface is seen: every point costs its unprojection, candidate
search and E-step, while a component's posterior, once it has a few hundred points'
worth of statistics, hardly moves. The frame is thinned by **systematic sampling with a
random start**: every ``s``-th pixel along each image axis, from an offset ``(oy, ox)``
drawn uniformly in ``[0, s)^2`` per frame under the map's key, ``s`` the smallest stride
whose grid of kept pixels fits the budget (:func:`stride`). Why this rule:

* it is decided from the frame's size alone, before unprojection: the work of a frame
  is bounded whatever it shows, and the kept count never exceeds the budget, so the
  compiled step's padded size is fixed for a stream (no recompilation per frame);
* each pixel is kept with probability exactly ``1 / s^2``, so weighting each kept point
  by ``s^2`` (``budget.weighted``) makes every sufficient statistic, ``sum_n r_nk
  phi(x_n)``, an unbiased estimate of the whole frame's (Horvitz-Thompson; tested);
* the kept pixels are still a lattice (a pixel grid of step ``s``), so the growth rule's
  covered area (:func:`vbgs.inference.grow.covered_area`: points x squared spacing) is
  the frame's own, and its cells the same as at full resolution.

Unbiased sums do not make a better posterior when a component gets only a point or two
of a frame: a weighted point counts ``s^2`` points of scatter that was never seen, and
the component's covariance collapses onto it. Unweighted (:data:`WEIGHTED`, the
default), the thinned frame counts as fewer points and the prior keeps its say. The
rule: the weighting that holds at every budget a user may ask for, on validation views
(``results/tuning/budget/room640.md``: the room at 640 x 480, 100k components, 18
frames, 2 validation views, the command and code in its first line). Weighted points
collapse at stride 4 (three dB under unweighted at 20k points) and lead at stride 2 by
about a tenth of a dB with a third more depth error: unweighted is the weighting that
holds. The default budget (:data:`POINTS`) by the rule of its comment, from
``room640_points_5k_40k.md`` and ``room640_points_60k_120k.md`` beside it;
``budget.saturation`` on top of it, and alone at every point, in
``room640_points80k_saturation.md`` and ``results/tuning/saturation/``. None was cheaper
than stride 2 alone (CPU seconds a frame on 2 cores, at an earlier code: stride 2 0.47,
with saturation 64 0.50, saturation 128 alone 1.22; the hashed counts and the
batch-sized compilations cost more than the 6 and 17% of the points they skip).

Scoring each pixel against the map to skip those already explained would need a
projection of the components or the E-step itself, the expensive work this is meant to
avoid; :mod:`vbgs.mapping.saturation` skips instead the points of growth cells that have
already taken ``budget.saturation`` points (a count per cell, no component read). With
``points = 0`` every valid pixel is learned, bit for bit as before; frames whose pixel
count is within the budget (fit-scene's 128 px) are not thinned either.
"""

from __future__ import annotations

import math

import jax
import numpy as np

from vbgs.render.camera import Camera, valid_depth

# Kept points count 1 each, not s^2 (module docstring: chosen on validation views).
WEIGHTED = False
# The default budget: a frame of more than this many pixels (a 640 x 480 sensor's) is
# learned on a lattice of stride 2; a frame of up to 320 x 240 pixels, fit-scene's 128 px
# among them, is learned whole. The rule: the coarsest stride within 0.2 dB of every
# point on validation views (results/tuning/budget/room640_points_5k_40k.md and
# _60k_120k.md: stride 2 is, stride 3 is not), and it halves a frame's time there
# (docs/performance.md). A fixed count, not a stride: what a frame's points buy is a few
# points per component, and 100k components at 640 x 480 are what 80k points serve;
# ``points = 0`` learns every pixel.
POINTS = 80000


def stride(width: int, height: int, points: int) -> int:
    """The smallest ``s >= 1`` with ``ceil(width / s) * ceil(height / s) <= points``: the
    kept pixels of any offset fit the budget (1 when ``points`` is 0: no budget)."""
    if points <= 0:
        return 1
    s = max(1, math.isqrt(max(width * height // points, 1)))
    while math.ceil(width / s) * math.ceil(height / s) > points:
        s += 1
    return s


def thin(depth: np.ndarray, points: int, *, key: jax.Array,
         weighted: bool = WEIGHTED) -> tuple[np.ndarray, np.ndarray | None]:
    """``depth [h, w]`` with every pixel off the sampled lattice set to 0 (missing), and
    each kept valid point's weight ``[n]`` in the order
    :func:`vbgs.render.camera.unproject` returns them (``s^2``; ones when not
    ``weighted``). A frame within the budget comes back as it is, with weight None."""
    depth = np.asarray(depth)
    h, w = depth.shape
    s = stride(w, h, points)
    if s == 1:
        return depth, None
    offset = tuple(int(v) for v in jax.random.randint(key, (2,), 0, s))
    return lattice(depth, s, offset, weighted=weighted)


def lattice(depth: np.ndarray, s: int, offset: tuple[int, int], *,
            weighted: bool = WEIGHTED) -> tuple[np.ndarray, np.ndarray]:
    """``depth [h, w]`` kept at rows ``oy, oy + s, ...`` and columns ``ox, ox + s, ...``
    (``offset = (oy, ox)``), 0 elsewhere, and the kept valid points' weights ``[n]``:
    ``s^2`` (each pixel's inverse chance of being kept), or ones."""
    oy, ox = offset
    if not (0 <= oy < s and 0 <= ox < s):
        raise ValueError(f"the offset {offset} must lie in [0, {s}) on both axes")
    out = np.zeros_like(depth)
    out[oy::s, ox::s] = depth[oy::s, ox::s]
    n = int(np.count_nonzero(valid_depth(out)))
    return out, np.full(n, float(s * s) if weighted else 1.0, np.float32)


def on_lattice(camera: Camera, pixel: np.ndarray, s: int) -> tuple[Camera, np.ndarray]:
    """A thinned frame's points as the frame of its lattice: the camera of the kept
    pixels alone (``ceil(w / s) x ceil(h / s)`` pixels, whatever the offset, so one
    compiled shape serves every frame; focal lengths ``f / s``, principal point
    ``(c - o - 1/2) / s + 1/2``, so a kept pixel's centre is its lattice pixel's) and
    their flat pixels ``[n]`` in it. ``pixel [n]``: their flat pixels in ``camera``'s
    image, all on one lattice of stride ``s`` (:func:`lattice`). The projective search
    lays a frame out by its pixels (:mod:`vbgs.inference.frame_tiles`): on the full
    image three in four slots of a stride-2 frame would be empty and scored all the
    same. ``s = 1``: the camera and pixels as they are."""
    if s == 1 or len(pixel) == 0:
        return camera, pixel
    w = int(camera.width)
    row, col = np.divmod(np.asarray(pixel, np.int64), w)
    oy, ox = int(row[0] % s), int(col[0] % s)
    if np.any(row % s != oy) or np.any(col % s != ox):
        raise ValueError(f"the pixels do not lie on one lattice of stride {s}")
    sub = camera._replace(fx=camera.fx / s, fy=camera.fy / s,
                          cx=(camera.cx - ox - 0.5) / s + 0.5,
                          cy=(camera.cy - oy - 0.5) / s + 0.5,
                          width=-(-w // s), height=-(-int(camera.height) // s))
    return sub, (row // s) * sub.width + col // s
