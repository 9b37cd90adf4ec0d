"""Front-to-back compositing of depth-sorted splats over a tile's pixels: the rules
(stated in :mod:`vbgs.render.raster`'s docstring) in one place, and the XLA compositing loop.

Shared by the XLA path (:func:`composite_tiles`) and the Pallas kernel
(:mod:`vbgs.render.raster_pallas`), which :func:`vbgs.render.raster.rasterize` chooses between:

    α_i = min(ALPHA_MAX, o_i exp(-½ dᵀ Σ'⁻¹ d)),  α_i := 0 where α_i < ALPHA_MIN,
    T_i = exp(max(Σ_{j<i} log(1 - α_j), LOG_T_MIN)),
    C = Σ_i c_i α_i T_i,  D = Σ_i z_i α_i T_i,  log T_final = Σ_i log(1 - α_i).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.precision import matmul
from vbgs.render.pixels import pixel_centre

ALPHA_MAX = 0.99  # clamp on a single splat's alpha (keeps 1 - α > 0 for the gradients)
ALPHA_MIN = 1.0 / 255.0  # contributions below one 8-bit colour step are skipped
POWER_FLOOR = float(np.log(ALPHA_MIN)) - 1.0  # exponent floor; exp(it) < ALPHA_MIN
LOG_T_MIN = -60.0  # transmittance is floored at e^-60 ≈ 9e-27 (see `transmittance`)
DEPTH_CHUNK = 64  # splats composited per step; steps past a tile's count are skipped


def alpha_from_offsets(du, dv, conic_a, conic_b, conic_c, opacity):
    """α of splats at pixel offsets ``du = p_u - u``, ``dv = p_v - v`` (broadcasting shapes,
    e.g. ``[p, m]`` offsets with ``[m]`` or ``[1, m]`` splat parameters), clamped and with
    small ones zeroed: ``α = min(ALPHA_MAX, o exp(q))``, ``q = -½ dᵀ Σ'⁻¹ d``, then 0 where
    ``α < ALPHA_MIN``. The one place of the alpha rule (XLA and Pallas paths).

    Written for speed on CPU without changing the result: q is floored at POWER_FLOOR
    (below it α < ALPHA_MIN for any o <= 1 anyway; the exp of a large negative number
    is a subnormal float, very slow on x86), and the threshold is the exact step
    ``floor(α - ALPHA_MIN) + 1`` (0 or 1 since 0 <= α < 1) because XLA's CPU code for
    compare-and-select is not vectorised. Elementwise only (no matrix products).
    """
    power = -0.5 * (conic_a * du * du + conic_c * dv * dv) - conic_b * du * dv
    alpha = jnp.minimum(ALPHA_MAX, opacity * jnp.exp(jnp.maximum(power, POWER_FLOOR)))
    return alpha * jax.lax.stop_gradient(jnp.floor(alpha - ALPHA_MIN) + 1.0)


def splat_alpha(pixels, uv, conic, opacity):
    """α [p, m] of m splats at p pixel centres ``pixels [p, 2]`` (see :func:`alpha_from_offsets`)."""
    du = pixels[:, None, 0] - uv[None, :, 0]  # [p, m]
    dv = pixels[:, None, 1] - uv[None, :, 1]
    return alpha_from_offsets(du, dv, conic[:, 0], conic[:, 1], conic[:, 2], opacity)


def chunk_weights(alpha, log_trans, log_before):
    """Compositing weights ``α_i T_i`` [p, m] of one depth-ordered chunk: ``alpha [p, m]``,
    ``log_trans [p]`` the log transmittance in front of the chunk and ``log_before [p, m]``
    the exclusive prefix sums ``Σ_{j<i} log(1 - α_j)`` within it, so that
    ``log T_i = log T + log_before_i`` (floored by :func:`transmittance`)."""
    return alpha * transmittance(log_trans[:, None] + log_before)


def _composite_chunk(carry, pixels, uv, conic, opacity, colour, depth):
    """Composite one depth-ordered chunk of m splats over p pixels, front to back.

    carry = (log T [p], C [p, 3], D [p]). Within the chunk the exclusive prefix sum
    ``Σ_{j<i} log(1 - α_j)`` is a product with a strictly upper-triangular matrix of
    ones (a small matmul is faster on CPU than a cumulative sum); the products run at
    full float32 precision (:func:`vbgs.inference.precision.matmul`), so TF32 cannot round them.
    """
    log_trans, rgb, dep = carry
    alpha = splat_alpha(pixels, uv, conic, opacity)  # [p, m]
    log1m = jnp.log1p(-alpha)
    m = alpha.shape[1]
    strict_upper = jnp.triu(jnp.ones((m, m), alpha.dtype), k=1)  # [j, i] = 1 where j < i
    weight = chunk_weights(alpha, log_trans, matmul(log1m, strict_upper))  # α_i T_i
    return (log_trans + jnp.sum(log1m, axis=1), rgb + matmul(weight, colour),
            dep + matmul(weight, depth))


def transmittance(log_t):
    """T = exp(max(log T, LOG_T_MIN)): floored far below float32 resolution of any output,
    which keeps subnormal floats (very slow on CPU) out of the arithmetic."""
    return jnp.exp(jnp.maximum(log_t, LOG_T_MIN))


def tile_pixel_coords(tile_id, n_tiles_x, tile):
    """Pixel centres ``(u [tile²], v [tile²])`` of tile ``tile_id`` (row-major tile grid,
    row-major pixels within the tile), from an iota (also inside a Pallas kernel)."""
    lane = jax.lax.broadcasted_iota(jnp.int32, (tile * tile,), 0)
    ty, tx = tile_id // n_tiles_x, tile_id % n_tiles_x
    u = pixel_centre((tx * tile + lane % tile).astype(jnp.float32))
    v = pixel_centre((ty * tile + lane // tile).astype(jnp.float32))
    return u, v


class TileSplats(NamedTuple):
    """Every tile's splats, nearest first, gathered from the projection (t tiles, c slots);
    slots past ``count`` have opacity 0."""

    uv: jax.Array  # [t, c, 2]
    conic: jax.Array  # [t, c, 3]
    opacity: jax.Array  # [t, c]
    colour: jax.Array  # [t, c, 3]
    depth: jax.Array  # [t, c]
    count: jax.Array  # [t] int32 splats used by the tile


def pad_slots(tiles: TileSplats, slots: int) -> TileSplats:
    """``tiles`` with its slot axis padded to ``slots`` (zeros: opacity 0, never composited)."""
    pad = slots - tiles.opacity.shape[1]

    def padded(x):
        return jnp.pad(x, ((0, 0), (0, pad)) + ((0, 0),) * (x.ndim - 2))

    return TileSplats(*(padded(x) for x in tiles[:5]), tiles.count)


def composite_tiles(tiles: TileSplats, *, n_tiles_x: int, tile: int):
    """Front-to-back compositing of every tile (the XLA path): ``(log T [t, p], C [t, p, 3],
    D [t, p])`` with p = tile² pixels. ``lax.map`` over tiles, ``lax.scan`` over chunks of
    DEPTH_CHUNK splats, a ``lax.cond`` skipping the chunks past the tile's count."""
    n_tiles, capacity = tiles.opacity.shape
    chunk = min(DEPTH_CHUNK, capacity)
    n_chunks = -(-capacity // chunk)
    tiles = pad_slots(tiles, n_chunks * chunk)

    def chunked(x):  # [t, c, ...] -> [t, n_chunks, chunk, ...]
        return x.reshape((n_tiles, n_chunks, chunk) + x.shape[2:])

    # Checkpointing per tile and per chunk keeps the backward pass's memory to the
    # chunk inputs; skipped chunks (past the tile's count) cost a branch only.
    @jax.checkpoint
    def one_tile(xs):
        tile_id, count, *chunks = xs
        pixels = jnp.stack(tile_pixel_coords(tile_id, n_tiles_x, tile), -1)  # [p, 2]

        def body(carry, xs):
            i, *chunk_params = xs
            carry = jax.lax.cond(
                i * chunk < count,
                lambda c: jax.checkpoint(_composite_chunk)(c, pixels, *chunk_params),
                lambda c: c,
                carry,
            )
            return carry, None

        p = tile * tile
        init = (jnp.zeros(p), jnp.zeros((p, 3)), jnp.zeros(p))  # log T, C, D
        carry, _ = jax.lax.scan(body, init, (jnp.arange(n_chunks), *chunks))
        return carry

    return jax.lax.map(
        one_tile, (jnp.arange(n_tiles), tiles.count, *(chunked(x) for x in tiles[:5])))
