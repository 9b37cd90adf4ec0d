"""The sparse E-step of a depth frame laid out in its tiles, every point of a tile scored
against the tile's candidates at once.

The projective search (:mod:`vbgs.inference.projective`) gives every point of a tile of
``T x T`` pixels the same ``C`` candidates. A frame's points are one per pixel, so a
tile holds at most ``P = T^2`` of them and the batch can be laid out as ``[tiles, P]``
(:func:`layout`: each point at its pixel's slot, empty slots of weight 0) instead of a
list. Then nothing per point is gathered or scattered:

* the candidates' E-step terms are gathered once per tile, ``[tiles, C]``, and the
  logits of the tile's points come by broadcasting (``[tiles, P, C]``);
* the statistics are per tile first, ``sum_p r_pc phi_p`` ``[tiles, C, F]``, and only
  then added into the components, ``tiles x C`` rows instead of ``n x C``. The per-tile
  sums are elementwise products summed over the tile's points, which XLA fuses into one
  reduction: on a 2-core CPU that took 61 ms against 89 ms as a batched product
  ``[tiles, C, P] x [tiles, P, F]`` for a recorded frame of the room at 640 x 480 under
  the Kinect (320 x 240 points, 4-pixel tiles; the whole E-step, minimum of 9, timed
  alone on a loaded machine), and 4.3 against 9.6 ms at 128 px (2-pixel tiles): a
  product of 16 x 16 x 16 is too small for a matrix unit to pay for its setup.

The per-point sparse E-step (:func:`vbgs.inference.model.e_step_with`) gathers ``16``
terms and scatters ``16`` (``28`` with measurement noise) moments for every point and
candidate. On a 640x480 frame of the room under the Kinect's noise (286k points, 16
candidates, 2-core CPU) the tiled E-step took 0.30 s with the 4-pixel tiles the room's
spacing gives, against 0.53 s point by point; 8-pixel tiles of 64 points took 0.15 s
(timed alone). The more points a tile holds, the more the tile shares; at 2-pixel tiles
it costs more than the per-point step. The result is the same E-step: the same
responsibilities, the same statistics up to the order of the sums
(``tests/vbgs/inference/test_frame_tiles.py`` holds the two to each other).

Precision: the logits are the per-point step's own centred elementwise terms
(:func:`vbgs.inference.candidates.scores`); the per-tile sums are elementwise float32
products and sums, so no matrix unit rounds them (under TF32 a GPU's products would round
the moments' centred coordinates to 10 bits).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from vbgs.inference import candidates
from vbgs.inference.expfam import Stats

# Tiles scored together (bounds the [tiles, P, C] temporaries: 256 tiles of 64 points
# and 16 candidates are 1 MB an array).
TILE_CHUNK = 256


class Layout(NamedTuple):
    """Where a batch's points sit in its frame's tiles (static sizes, device arrays)."""

    slot: jnp.ndarray  # [n] int32: tile * P + the pixel's place in its tile (tiles * P: none)
    tiles: int  # with the spare border ring of the projective tiling
    per_tile: int  # P = T^2


def layout(pixel: jnp.ndarray, tiling) -> Layout:
    """The :class:`Layout` of points seen at the flat pixel indices ``pixel [n]`` (row
    major in the ``tiling``'s frame; -1: padding) in the tiles of ``tiling``
    (:class:`vbgs.inference.projective.Tiling`: tile side ``T``, one spare tile round
    the image). Each pixel has one slot, so points of distinct pixels never share one."""
    t = tiling.tile
    row, col = pixel // tiling.width, pixel % tiling.width
    tile = (row // t + 1) * tiling.tiles_x + col // t + 1
    n_tiles = tiling.tiles_x * tiling.tiles_y
    padded = padded_tiles(n_tiles)
    slot = jnp.where(pixel >= 0, tile * t * t + (row % t) * t + col % t, padded * t * t)
    return Layout(slot.astype(jnp.int32), padded, t * t)


def padded_tiles(n_tiles: int) -> int:
    """The tiles of a layout: ``n_tiles`` rounded up to whole chunks of :func:`chunk`
    tiles (the extra tiles stay empty)."""
    c = chunk(n_tiles)
    return -(-n_tiles // c) * c


def chunk(n_tiles: int) -> int:
    """Tiles per scan step of :func:`e_step`."""
    return max(1, min(TILE_CHUNK, n_tiles))


def gridded(a: jnp.ndarray, where: Layout, fill=0) -> jnp.ndarray:
    """Per-point values ``a [n, ...]`` laid out as ``[tiles, P, ...]`` (``fill`` in the
    slots no point holds)."""
    size = where.tiles * where.per_tile
    out = jnp.full((size + 1,) + a.shape[1:], fill, a.dtype).at[where.slot].set(a)
    return out[:size].reshape((where.tiles, where.per_tile) + a.shape[1:])


def pointwise(a: jnp.ndarray, where: Layout) -> jnp.ndarray:
    """The inverse of :func:`gridded`: ``[tiles, P, ...]`` back to the points ``[n, ...]``
    (0 for padding)."""
    flat = a.reshape((-1,) + a.shape[2:])
    flat = jnp.concatenate([flat, jnp.zeros((1,) + flat.shape[1:], flat.dtype)])
    return flat[where.slot]


def tile_depths(z: jnp.ndarray, w: jnp.ndarray) -> jnp.ndarray:
    """Each tile's nearest, mean and farthest depth of its points of positive weight,
    ``[tiles, 3]`` (+inf where it holds none): ``z``, ``w`` ``[tiles, P]``."""
    held = w > 0
    count = held.sum(-1)
    near = jnp.min(jnp.where(held, z, jnp.inf), -1)
    far = jnp.max(jnp.where(held, z, -jnp.inf), -1)
    mean = jnp.where(held, z, 0.0).sum(-1) / jnp.maximum(count, 1)
    return jnp.stack([near, jnp.where(count > 0, mean, jnp.inf),
                      jnp.where(count > 0, far, jnp.inf)], -1)


def nearest_distance(means: jnp.ndarray, x: jnp.ndarray, cand: jnp.ndarray) -> jnp.ndarray:
    """Each point's squared distance to the nearest of its tile's candidates ``[tiles,
    P]`` (inf where the tile lists none): ``x [tiles, P, d]``, ``cand [tiles, C]``."""
    near = means[jnp.maximum(cand, 0)]  # [tiles, C, d]
    d2 = sum((x[..., i, None] - near[:, None, :, i]) ** 2 for i in range(x.shape[-1]))
    return jnp.min(jnp.where(cand[:, None, :] >= 0, d2, jnp.inf), -1)


def e_step(terms, x: jnp.ndarray, c: jnp.ndarray, w: jnp.ndarray, cand: jnp.ndarray,
           colour_noise: float, ray: jnp.ndarray | None = None
           ) -> tuple[Stats, jnp.ndarray]:
    """:func:`vbgs.inference.model.e_step_with`'s sparse E-step for points laid out in
    tiles, ``x [tiles, P, d]``, ``c [tiles, P, 3]``, ``w [tiles, P]`` (0: no point),
    ``ray [tiles, P, d]`` (measured points' noise along their rays, or None), every
    point of a tile scored against the tile's candidates ``cand [tiles, C]`` (-1: none
    listed; those take no responsibility). Returns the summed statistics and each
    slot's ``log sum_c exp(l_pc)`` ``[tiles, P]``. ``terms``: the assigning model's
    :class:`vbgs.inference.model.Terms`."""
    from vbgs.inference import model  # model imports this module's callers

    n_tiles, per, d = x.shape
    k = terms.mean.shape[0]
    step = chunk(n_tiles)
    width = d * d + d + 4

    def one_chunk(acc, batch):
        xb, cb, wb, candb, rayb = batch
        listed, candb = candb >= 0, jnp.maximum(candb, 0)
        g = [row[:, None, :] for row in candidates.gathered(terms, candb)]  # [t, 1, C]
        logits, a, q = candidates.scores(xb, cb, g, colour_noise, rayb)
        logits = jnp.where(listed[:, None, :], logits, jnp.finfo(logits.dtype).min / 2)
        lse = jax.nn.logsumexp(logits, -1)  # [t, P]
        resp = jnp.exp(logits - lse[..., None]) * wb[..., None]  # [t, P, C]
        phi = model.features(xb.reshape(-1, d), cb.reshape(-1, 3)).reshape(xb.shape[:2] + (-1,))
        rows = [_per_tile(resp, phi)]  # [t, C, F]
        if rayb is not None:  # the latent moments (model.e_step_with), summed per tile
            (b, sym), (g, uu), (_, u) = candidates.latent_moments(
                *candidates.latent_shift(a, q), xb, rayb)
            rb = resp * b
            rows += [_per_tile(rb, sym) + _per_tile(resp * g, uu), _per_tile(rb, u)]
        rows = jnp.concatenate(rows, -1)  # [t, C, width (+ d * d + d)]
        return acc.at[candb.reshape(-1)].add(rows.reshape(-1, rows.shape[-1])), lse

    def shape(a):
        return None if a is None else a.reshape((n_tiles // step, step) + a.shape[1:])

    acc0 = jnp.zeros((k, width + (0 if ray is None else d * d + d)), x.dtype)
    acc, lse = jax.lax.scan(one_chunk, acc0, (shape(x), shape(c), shape(w), shape(cand),
                                              shape(ray)))
    return model.moments_to_stats(acc, d), lse.reshape(n_tiles, per)


def _per_tile(resp: jnp.ndarray, phi: jnp.ndarray) -> jnp.ndarray:
    """``sum_p resp[t, p, c] phi[t, p, f]``: ``[t, C, F]``, elementwise in float32 (see the
    module docstring)."""
    return jnp.sum(resp[:, :, :, None] * phi[:, :, None, :], axis=1)
