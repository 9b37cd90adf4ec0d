"""A measured frame's holes behind depth edges, given the depth of the surface they
continue.

A depth sensor returns no depth where a surface is: on both sides of a depth edge, at
grazing angles, at random (:mod:`vbgs.sensors.holes`). Such a pixel is neither free space
nor background (:func:`vbgs.render.background.empty_pixels` tells those apart): it shows
a surface whose colour is measured and whose depth is not. The far side of a depth edge
is the costly one: the ground just behind an object's silhouette lies beside that edge
in every view, so left out it gets no points, hence no components, and every view of
it shows the background (object, 64 px / 5000 components / 20 frames, physical holes:
giving the learner's points the exact depth of the far sides alone lifts it from 21.15
to 22.79 dB, of the near sides alone to 22.25; the opacity evidence, the background
estimate and the empty pixels given the exact depth change nothing).

A hole takes the depth of the surface through its nearest pixels with depth of the same
colour: within ``radius`` pixels (rings of growing distance, nearest first; within a
ring the neighbour whose colour differs least, by at most ``tol`` in every channel),
carried on by one step (inverse depth is affine in the pixel coordinates on a plane:
``1/z = 2/z1 - 1/z2`` from the neighbour and the one beyond it; ``z1`` where that one has
none). It is kept only on the far side of an edge: within ``radius + 1`` pixels of a
measured surface nearer than it by more than :data:`EDGE_FOOTPRINTS` pixel footprints,
and not within as many of an empty pixel or of a surface farther by as much (the near
side, a rim, which other views see head-on; filled there, a rounded rim's depth is far
off and draws a fringe around the silhouettes: object 128 px / 20k / 60 frames, Kinect,
validation, radius 1 and tol 0.3: 22.81 dB with rims filled, 23.98 without, 23.66 with
no fill). A hole inside a surface (a random dropout) stays a hole: other frames see that
ground, and filled, random 5% holes lost 0.36 dB on the object's validation views (64 px,
22.79 against 23.15 dB; far sides only: 23.14).
The filled pixels become points like the others; the opacity evidence still reads the
measured depth (a hole proves nothing about what a ray passed through,
:mod:`vbgs.render.opacity`).

Where the rest of the holes' cost lies (object, 128 px / 20k / 60 frames, the Kinect's
holes at noise level 0, validation views; 25.15 dB, exact depth 26.58): the far sides'
fill is not it (their pixels given the true depth: 25.15); the rims are (every hole
within 2 px of an empty pixel given its true depth: 26.10; the holes inside surfaces:
25.29; all holes: 26.11). Approximate rim depths cost more than the rims are worth:
the nearest measured depth (no colour test) 22.90, the map's own rendered depth where
it covers the pixel (alpha > 0.5) 23.23, the nearest depth only for rims unlike every
measured neighbour in colour 23.60: points a little off a silhouette are seen from
other views as a shell over the surface.

Which rims (object, 64 px / 5000 / 20 frames, the Kinect's physical holes at
level 0, validation views; one-off scripts patching the training depth or the mapper):
no fill 22.67 dB; every rim hole (within 2 px of an empty pixel: 58% of the holes) given
its true depth 23.39. The 85% of them whose true depth lies within 4 pixel footprints of
a measured pixel within 2 px (a surface continued to its silhouette) carry it all: those
alone 23.24, the other 15% alone 22.67. Yet the nearest measured depth within 2 px, on
every rim, gives 19.78 (only beside measured pixels whose depth changes less than 2 or
1 footprints a pixel: 19.81, 20.57); and at 128 px / 20k / 60 frames under the Kinect
(level 1, its own holes; 24.61 without) the same fill learned as uncertain along its
ray (2 footprints, the measurement model's latent depth) gives 21.22. A few footprints'
error on a silhouette costs more than the silhouette's points are worth.
Nor do other frames' measurements place them (the same 64 px runs, 8 validation
views: exact depth 23.09 dB, no fill 22.56): each rim given the nearest depth the last 8
arrived frames measured inside its pixel (their points z-buffered into the frame), kept
only within 4, 1, 1 or 0.5 footprints of a measured pixel within 2 px (and seen by 1, 1,
3 or 2 of the frames): 21.99, 22.22, 22.11, 22.11 dB, 42 to 20 % of the rims filled. Inside a pixel at a
silhouette the surface spans several footprints of depth: the nearest point in it is
not the depth the pixel's centre ray meets.
"""

from __future__ import annotations

import functools
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.mapping.image_shifts import padded, shifted
from vbgs.render.camera import valid_depth

# Pixels a hole's depth may come from; 0: holes stay holes. Chosen on validation views,
# rule: the best mean PSNR over the object and the room (64 px, 5000 components, 20
# frames, a Kinect's own holes without its noise; results/tuning/holes/mean.md, made by
# python -m experiments.run tune --scene object room --size 64 --components 5000 --frames
# 20 --simulate-sensor kinect --sensor-level 0 --sensor-holes physical --sensor kinect
# --grid growth.hole_radius=0,1,2 growth.hole_colour_tol=0.15,0.3,1 --out
# results/tuning/holes): filling scores above leaving the holes at radius 1 and 2 (the
# object gains, the room, whose 5000 components are all spent, loses a little at the
# colour tolerance below). An earlier one-off run at 128 px / 20k / 60 frames with the
# Kinect's noise and holes gave 24.50 dB with the fill against 23.66 without. Radius 2
# scores 0.03 dB over 1 at the tolerance below, under the 0.1 dB a move needs: 1 kept.
HOLE_RADIUS = 1
# Largest difference in any colour channel ([0, 1]) between a hole and the neighbour
# whose surface it continues. Same table: at radius 1 the best mean is 1.0 (no colour
# test), 0.05 dB over 0.15, all of it the room's (the object ties); not moved, as one
# scene at 64 px is not a clear gain and the Kinect results would all be made again.
HOLE_COLOUR_TOL = 0.15
# A surface nearer than a neighbour by more than this many pixel footprints (z / focal)
# is across a depth edge from it (a surface inclined 76 degrees from the ray changes by 4
# footprints a pixel). Set from that geometry, not tuned.
EDGE_FOOTPRINTS = 4.0


def ring_offsets(radius: int) -> list[list[tuple[int, int]]]:
    """The pixel offsets ``(dy, dx)`` within ``radius`` (Euclidean, the centre left out),
    grouped into rings of equal distance, nearest first."""
    rings: dict[int, list[tuple[int, int]]] = {}
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            d2 = dy * dy + dx * dx
            if 0 < d2 <= radius * radius:
                rings.setdefault(d2, []).append((dy, dx))
    return [rings[d2] for d2 in sorted(rings)]


def fill_holes(depth: np.ndarray, rgb: np.ndarray, empty: np.ndarray, focal: float,
               radius: int = HOLE_RADIUS, tol: float = HOLE_COLOUR_TOL) -> np.ndarray:
    """``depth [h, w]`` with the holes behind its depth edges filled (module docstring):
    pixels without depth that are not ``empty [h, w]`` (bool: showing nothing) take the
    depth extrapolated from the nearest pixel with depth within ``radius`` whose ``rgb
    [h, w, 3]`` differs by at most ``tol`` in every channel, unless that makes them a rim
    or they lie beside no nearer surface; ``focal``: the focal length in pixels (a
    footprint is z / focal). Pixels with depth are unchanged (of ``depth``'s dtype);
    ``radius`` 0 returns ``depth`` itself.

    One compiled function per frame shape and ``radius`` (:func:`_filled`; 4 ms
    against 97 ms for the NumPy loops over shifted copies it replaced, 640 x 480, 2 CPU
    cores), in float32: depth in scene units needs no more (an extrapolation is kept or
    dropped by comparisons at 4 footprints, a relative 4 / focal of some 1e-2, against
    float32's 6e-8). A float32 depth comes out to the bit as those loops gave it on the
    CPU (the same IEEE operations in the same order); a float64 one is rounded to
    float32 for the fill."""
    depth = np.asarray(depth)
    ok = valid_depth(depth)
    empty = np.asarray(empty, bool)
    if radius <= 0 or not (~ok & ~empty).any() or not ok.any():
        return depth
    out = np.asarray(_filled(depth.astype(np.float32, copy=False), np.asarray(rgb, np.float32),
                             empty, np.float32(focal), np.float32(tol), int(radius)))
    return out if depth.dtype == np.float32 else np.where(ok, depth, out.astype(depth.dtype))


@partial(jax.jit, static_argnames="radius")
def _filled(depth: jax.Array, rgb: jax.Array, empty: jax.Array, focal: jax.Array,
            tol: jax.Array, radius: int) -> jax.Array:
    """``[h, w]`` float32: ``depth [h, w]`` where valid, else the holes' filled depth (0
    where left), given ``rgb [h, w, 3]`` and ``empty [h, w]`` (bool); the ring offsets
    unrolled, each shift a slice of one padded copy (:func:`fill_holes`)."""
    h, w = depth.shape
    ok = jnp.isfinite(depth) & (depth > 0)  # valid_depth
    known = jnp.where(ok, depth, 0.0)
    todo = ~ok & ~empty
    reach = radius + 1
    pad = 2 * reach
    known_p = padded(known, pad, 0.0)
    planes = [rgb[..., c] for c in range(3)]  # one fused loop, no [h, w, 3] copies
    planes_p = [padded(p, radius, jnp.inf) for p in planes]
    out = known
    for ring in ring_offsets(radius):
        best_diff = jnp.full(known.shape, jnp.inf, jnp.float32)
        best_depth = jnp.zeros_like(known)
        for dy, dx in ring:
            z = _extrapolated(shifted(known_p, pad, dy, dx, h, w),
                              shifted(known_p, pad, 2 * dy, 2 * dx, h, w))
            diff = functools.reduce(jnp.maximum, [  # [h, w] the largest channel's
                jnp.abs(planes[c] - shifted(planes_p[c], radius, dy, dx, h, w))
                for c in range(3)])
            better = (z > 0) & (diff < best_diff)
            best_diff = jnp.where(better, diff, best_diff)
            best_depth = jnp.where(better, z, best_depth)
        take = todo & (best_diff <= tol)
        out = jnp.where(take, best_depth, out)
        todo = todo & ~take
    filled = ~ok & (out > 0)
    rim, behind = _sides(out, known_p, padded(empty, reach, False), pad, focal, reach)
    return jnp.where(ok, depth, jnp.where(filled & (rim | ~behind), 0.0, out))


def _extrapolated(z1: jax.Array, z2: jax.Array) -> jax.Array:
    """Per pixel, the depth of the surface through a neighbour ``z1`` and the one beyond
    it ``z2`` (0: no depth) carried on by one step, ``1/z = 2/z1 - 1/z2``; ``z1`` where
    the second has no depth; 0 where the first has none."""
    w = jnp.where((z1 > 0) & (z2 > 0), 2.0 / z1 - 1.0 / z2, 1.0 / z1)
    return jnp.where((z1 > 0) & (w > 0), 1.0 / w, 0.0)


def _sides(filled: jax.Array, known_p: jax.Array, empty_p: jax.Array, pad: int,
           focal: jax.Array, reach: int) -> tuple[jax.Array, jax.Array]:
    """``[h, w]`` bool each: the rims, pixels within ``reach`` of an empty pixel or of a
    measured surface farther than their ``filled`` depth by more than
    :data:`EDGE_FOOTPRINTS` footprints (the near side of a depth edge); and the pixels
    within ``reach`` of a measured surface nearer by as much (the far side).
    ``known_p``, ``empty_p``: the measured depth and the empty pixels padded by ``pad``
    and ``reach`` pixels (0, False)."""
    h, w = filled.shape
    # (4 z) / f rounded as written: XLA turns a division by a scalar into a product
    # with its reciprocal, which rounds differently; the barrier keeps the division
    jump = EDGE_FOOTPRINTS * filled / jax.lax.optimization_barrier(
        jnp.broadcast_to(focal, filled.shape))
    rim = jnp.zeros(filled.shape, bool)
    behind = jnp.zeros(filled.shape, bool)
    for ring in ring_offsets(reach):
        for dy, dx in ring:
            rim |= shifted(empty_p, reach, dy, dx, h, w)
            other = shifted(known_p, pad, dy, dx, h, w)
            rim |= other > filled + jump
            behind |= (other > 0) & (other < filled - jump)
    return rim, behind
