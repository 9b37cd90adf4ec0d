"""The rasterizer's compositing as a Pallas kernel (``jax.experimental.pallas``), for GPUs.

Same inputs and outputs as :func:`vbgs.render.composite.composite_tiles`, the XLA path: the
tiles' depth-sorted splat lists that :func:`vbgs.render.raster.tile_splats` gathers from the
projection and :func:`vbgs.render.raster.tile_lists`. Only the compositing loop differs.

Kernel. A grid of one program per tile; each program holds the tile's p = tile²
pixels as one block of lanes and its ``c`` splat slots (every splat parameter a
``[1, c]`` row, c a power of two), and walks the first ``count`` slots front to back
in chunks of m = DEPTH_CHUNK splats (``fori_loop`` up to ``ceil(count / m)``: the
early stop at the tile's count). Per chunk, with the rules of :mod:`vbgs.render.raster`
(one formula in one place, :mod:`vbgs.render.composite`: :func:`~vbgs.render.composite.alpha_from_offsets`,
:func:`~vbgs.render.composite.chunk_weights`, :func:`~vbgs.render.composite.transmittance`):

    α [p, m]               = alpha_from_offsets(p_u - u, p_v - v, a, b, c, o),
    log_before_i [p, m]    = Σ_{j<i} log(1 - α_j)    (cumsum minus the term itself),
    w_i [p, m]             = α_i exp(max(log T + log_before_i, LOG_T_MIN)),
    C += Σ_i w_i c_i,  D += Σ_i w_i z_i,  log T += Σ_i log(1 - α_i).

Everything is elementwise products, exp/log and row sums: no matrix product, so
TF32 cannot round anything. Block shapes are static powers of two (the tile must be
a power of two; the slot axis is padded to one), so the kernel lowers to Triton on
a GPU; elsewhere it runs with ``interpret=True`` (slow, for tests).

Gradients. :func:`composite_tiles_pallas` is a ``jax.custom_jvp`` whose tangent is the
XLA path's (:func:`vbgs.render.composite.composite_tiles`) at the same inputs; reverse
mode transposes it, so the gradients are the XLA path's and a backward pass costs what
it costs there (the XLA forward's intermediates are computed beside the kernel's
output). Forward mode works too (``jax.jacfwd``, as the colour fit's tests use). The
kernel computes in float32; other dtypes (float64 under ``jax.enable_x64``) take the
XLA path.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as pl_triton

from vbgs.render.composite import (
    DEPTH_CHUNK,
    TileSplats,
    alpha_from_offsets,
    chunk_weights,
    composite_tiles,
    pad_slots,
    tile_pixel_coords,
)

NUM_WARPS = 4  # Triton warps per tile program (256 pixel lanes at tile 16: 2 per thread)
# Splat parameters handed to the kernel, one [t, c] row array each, in this order.
FIELDS = ("u", "v", "conic_a", "conic_b", "conic_c", "opacity", "red", "green", "blue", "depth")


def _rows(tiles: TileSplats) -> list[jax.Array]:
    """The splat parameters of every tile as FIELDS arrays ``[t, c]`` each."""
    return [tiles.uv[..., 0], tiles.uv[..., 1], *jnp.moveaxis(tiles.conic, -1, 0),
            tiles.opacity, *jnp.moveaxis(tiles.colour, -1, 0), tiles.depth]


def _kernel(count_ref, *refs, n_tiles_x: int, tile: int, chunk: int):
    """One tile: composite its first ``count`` slots front to back into the output rows
    log T, C (three channels) and D, ``[1, p]`` blocks each."""
    params, (log_t_out, red_out, green_out, blue_out, depth_out) = refs[:-5], refs[-5:]
    px, py = tile_pixel_coords(pl.program_id(0), n_tiles_x, tile)  # [p] each
    px, py = px[:, None], py[:, None]  # [p, 1]
    n_chunks = (count_ref[0] + chunk - 1) // chunk

    def body(i, carry):
        log_t, red, green, blue, dep = carry  # [p] each
        slots = pl.ds(pl.multiple_of(i * chunk, chunk), chunk)
        u, v, a, b, c, o, r, g, bl, z = (ref[:, slots] for ref in params)  # [1, m] each
        alpha = alpha_from_offsets(px - u, py - v, a, b, c, o)  # [p, m]
        log1m = jnp.log1p(-alpha)
        weight = chunk_weights(alpha, log_t, jnp.cumsum(log1m, axis=1) - log1m)  # [p, m]
        return (log_t + jnp.sum(log1m, axis=1), red + jnp.sum(weight * r, axis=1),
                green + jnp.sum(weight * g, axis=1), blue + jnp.sum(weight * bl, axis=1),
                dep + jnp.sum(weight * z, axis=1))

    zeros = jnp.zeros((tile * tile,), jnp.float32)
    out = jax.lax.fori_loop(0, n_chunks, body, (zeros,) * 5)
    for ref, value in zip((log_t_out, red_out, green_out, blue_out, depth_out), out,
                          strict=True):
        ref[...] = value[None, :]


def _pallas_forward(tiles: TileSplats, n_tiles_x: int, tile: int, interpret: bool):
    """The kernel over all tiles: ``(log T [t, p], C [t, p, 3], D [t, p])``."""
    n_tiles, capacity = tiles.opacity.shape
    chunk = min(DEPTH_CHUNK, 1 << max(0, capacity - 1).bit_length())
    slots = max(chunk, 1 << max(0, capacity - 1).bit_length())  # power of two, >= chunk
    tiles = pad_slots(tiles, slots)
    p = tile * tile
    row = pl.BlockSpec((1, slots), lambda t: (t, 0))
    out_row = pl.BlockSpec((1, p), lambda t: (t, 0))
    log_t, red, green, blue, dep = pl.pallas_call(
        functools.partial(_kernel, n_tiles_x=n_tiles_x, tile=tile, chunk=chunk),
        grid=(n_tiles,),
        in_specs=[pl.BlockSpec((1,), lambda t: (t,))] + [row] * len(FIELDS),
        out_specs=[out_row] * 5,
        out_shape=[jax.ShapeDtypeStruct((n_tiles, p), jnp.float32)] * 5,
        interpret=interpret,
        compiler_params=pl_triton.CompilerParams(num_warps=NUM_WARPS),  # Triton, not Mosaic GPU
    )(tiles.count.astype(jnp.int32), *(x.astype(jnp.float32) for x in _rows(tiles)))
    return log_t, jnp.stack([red, green, blue], -1), dep


@functools.partial(jax.custom_jvp, nondiff_argnums=(1, 2, 3))
def _composite(tiles: TileSplats, n_tiles_x: int, tile: int, interpret: bool):
    return _pallas_forward(tiles, n_tiles_x, tile, interpret)


@_composite.defjvp
def _composite_jvp(n_tiles_x, tile, interpret, primals, tangents):
    """The kernel's output and the XLA path's tangent at the same inputs (the integer
    counts carry none). Linear in the tangents, so reverse mode transposes it: the
    gradients are the XLA path's, and forward mode (``jax.jvp``, ``jax.jacfwd``) works
    too, which a custom VJP would refuse."""
    (tiles,), (d_tiles,) = primals, tangents

    def xla(uv, conic, opacity, colour, depth):
        return composite_tiles(TileSplats(uv, conic, opacity, colour, depth, tiles.count),
                               n_tiles_x=n_tiles_x, tile=tile)

    _, out_dot = jax.jvp(xla, tuple(tiles[:5]), tuple(d_tiles[:5]))
    return _pallas_forward(tiles, n_tiles_x, tile, interpret), out_dot


def composite_tiles_pallas(tiles: TileSplats, *, n_tiles_x: int, tile: int,
                           interpret: bool = False):
    """Front-to-back compositing of every tile by the Pallas kernel: ``(log T [t, p],
    C [t, p, 3], D [t, p])``, p = tile², as :func:`vbgs.render.composite.composite_tiles` returns.
    ``tile`` must be a power of two; ``interpret=True`` runs the kernel without a GPU.
    Differentiable in both modes through a custom JVP: the XLA path's tangent at the same
    inputs. Inputs other than float32 take the XLA path."""
    if tile <= 0 or tile & (tile - 1):
        raise ValueError(f"the Pallas rasterizer needs a power-of-two tile, got {tile}")
    if tiles.uv.dtype != jnp.float32:  # the kernel computes in float32: float64 (x64
        return composite_tiles(tiles, n_tiles_x=n_tiles_x, tile=tile)  # tests) stays exact
    return _composite(tiles, n_tiles_x, tile, interpret)
