"""Differentiable tile-based rasterizer for 3-D Gaussian splats, and a slow reference.

Projection (EWA splatting). A splat with world mean μ and covariance Σ is seen by a
pinhole camera with world-to-camera rotation W and translation b at camera-space
mean ``t = W μ + b`` (depth ``z = t_z``). Its image is the 2-D Gaussian with mean
``(u, v) = (fx t_x / z + cx, fy t_y / z + cy)`` and covariance

    Σ' = J W Σ Wᵀ Jᵀ + BLUR_VARIANCE · I,
    J  = [[fx / z, 0, -fx t_x / z²],
          [0, fy / z, -fy t_y / z²]],

J being the Jacobian of the perspective projection at t; the added
``BLUR_VARIANCE`` (px²) is the usual low-pass dilation that keeps every splat at
least about a pixel wide.

Where splats may be (the camera inside a room sees splats beside and behind it):

* **near plane**: splats with ``z <= near`` (default ``NEAR`` = 0.2 scene units,
  as 3DGS) are culled; close to the camera the linearisation behind J breaks down.
* **clamped Jacobian**: J is evaluated at ``t_x / z, t_y / z`` clamped to
  ``FRUSTUM_CLAMP`` (1.3) times the frustum's extent on each side of the optical
  axis (``-cx / fx .. (w - cx) / fx`` in x, likewise in y), as 3DGS does. Without
  it the ``-fx t_x / z²`` column grows without bound for splats far off-axis, and
  a small splat beside the camera gets a footprint that covers the whole image.
  The mean ``(u, v)`` itself is projected exactly.
* **frustum culling with a guard band**: splats whose mean lies beyond
  ``FRUSTUM_CULL`` (2) times that extent are culled; the band between 1.3 and 2
  keeps splats just outside the view that still reach into it.
* **bounded footprint**: a splat whose projected standard deviation exceeds
  ``MAX_FOOTPRINT`` (1) image sizes (the longer side) is culled: no single
  Gaussian is meant to paint the whole picture, and one that would is almost
  always a splat grazing the near plane.

Compositing. At pixel centre p, splat i (in increasing depth) has

    α_i = min(ALPHA_MAX, o_i exp(-½ dᵀ Σ'_i⁻¹ d)),  d = p - (u_i, v_i),

and contributions with ``α_i < ALPHA_MIN`` are skipped (α_i := 0). Front to back,

    T_i = Π_{j<i} (1 - α_j),   C = Σ_i c_i α_i T_i,   D = Σ_i z_i α_i T_i,
    alpha = 1 - T_final,        rgb = C + T_final · background.

D is the *expected* depth with empty space counted as depth 0; it is not divided
by alpha. Divide by ``alpha`` yourself for the depth of the visible surface.
T is floored at ``exp(LOG_T_MIN)`` ≈ 9e-27 (far below float32 resolution of any
output) so that no subnormal floats, which are very slow on x86, enter the sums.

Tiles. The image is cut into ``tile x tile`` pixel tiles. A splat can only reach
pixels where ``o exp(-½ m²) >= ALPHA_MIN``, i.e. within Mahalanobis radius
``m_max = sqrt(2 ln(o / ALPHA_MIN))`` (<= 3.33 for o <= 1); the axis-aligned box of
that ellipse, ``(u, v) ± m_max (sqrt Σ'_uu, sqrt Σ'_vv)``, is tested against each
tile. Unlike a fixed 3-sigma box this bound is exact, so the tiled renderer
equals :func:`vbgs.raster_reference.render_reference` whenever nothing is dropped. Each tile keeps the
``capacity`` nearest overlapping splats; the rest (the farthest) are *dropped*
and counted in ``RenderOutput.dropped`` (once per splat and tile). Check it, e.g.
``assert int(out.dropped) == 0`` or call :func:`check_dropped`, and raise
``capacity`` (or lower ``tile``) if it is not zero; :func:`required_capacity`
gives the smallest capacity that drops nothing for a given view.

Implementation (chosen by measurement on a 2-core CPU, see
``experiments/bench_raster.py``): one depth sort of the splats; one int32 sort of
(tile, depth rank) keys gives every tile its nearest ``capacity`` splats
(:func:`tile_lists`); then ``lax.map`` over tiles and ``lax.scan`` over chunks of
DEPTH_CHUNK splats, where a ``lax.cond`` skips the chunks past the tile's count,
so the compositing cost follows the actual overlaps rather than the capacity.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.camera import Camera
from vbgs.pixels import pixel_centre
from vbgs.splats import Splats, check_splats

BLUR_VARIANCE = 0.3  # px², low-pass dilation added to every projected covariance
ALPHA_MAX = 0.99  # clamp on a single splat's alpha (keeps 1 - α > 0 for the gradients)
ALPHA_MIN = 1.0 / 255.0  # contributions below one 8-bit colour step are skipped
POWER_FLOOR = float(np.log(ALPHA_MIN)) - 1.0  # exponent floor; exp(it) < ALPHA_MIN
LOG_T_MIN = -60.0  # transmittance is floored at e^-60 ≈ 9e-27 (see `transmittance`)
DEFAULT_TILE = 16  # tile side in pixels (measured best of 8/16/32 on a 2-core CPU)
DEFAULT_CAPACITY = 2048  # splats kept per tile, nearest first (8 per pixel at tile 16)
NEAR = 0.2  # default near plane (scene units, camera z), as 3DGS
FRUSTUM_CLAMP = 1.3  # J is evaluated with x/z, y/z clamped to 1.3x the frustum extent (3DGS)
FRUSTUM_CULL = 2.0  # means beyond 2x the frustum extent are culled (guard band beyond the clamp)
MAX_FOOTPRINT = 1.0  # splats whose projected sigma exceeds 1 image size (longer side) are culled
DEPTH_CHUNK = 64  # splats composited per step; steps past a tile's count are skipped
SURFACE_ALPHA = 0.5  # rendered depth counts only where the splats cover the pixel this much


class RenderOutput(NamedTuple):
    """What :func:`rasterize` returns."""

    rgb: jax.Array  # [h, w, 3]
    depth: jax.Array  # [h, w] expected depth Σ z_i α_i T_i (not normalised)
    alpha: jax.Array  # [h, w] 1 - T_final
    dropped: jax.Array  # [] int32 (splat, tile) overlaps left out for lack of capacity; 0: exact


class Projected(NamedTuple):
    """Splats projected to the image (per splat, k rows)."""

    uv: jax.Array  # [k, 2] image position of the mean (px)
    conic: jax.Array  # [k, 3] (a, b, c) of Σ'⁻¹ = [[a, b], [b, c]]
    depth: jax.Array  # [k] camera z of the mean
    opacity: jax.Array  # [k] opacity, 0 where culled
    extent: jax.Array  # [k, 2] half-size (px) of the box where α can reach ALPHA_MIN
    visible: jax.Array  # [k] bool: in front of the near plane and not too faint


def frustum_tangents(fx, fy, cx, cy, width, height):
    """The view's extent on each side of the optical axis as tangents ``x/z``, ``y/z``:
    ``(lo [2], hi [2])`` with ``lo = -(cx, cy) / (fx, fy)``, ``hi = ((w, h) - (cx, cy)) / (fx, fy)``."""
    f = jnp.stack([jnp.asarray(fx), jnp.asarray(fy)])
    c = jnp.stack([jnp.asarray(cx), jnp.asarray(cy)])
    return -c / f, (jnp.array([width, height], f.dtype) - c) / f


def project(
    splats: Splats, fx, fy, cx, cy, pose, near=NEAR, blur=BLUR_VARIANCE, *, width: int,
    height: int,
) -> Projected:
    """EWA projection of every splat with culling and a clamped Jacobian (see the module
    docstring). ``pose``: [4, 4] camera-to-world; ``width``/``height``: the image size (px)."""
    pose = jnp.asarray(pose, splats.means.dtype)
    rot_wc = pose[:3, :3].T  # W, world -> camera
    t_cam = (splats.means - pose[:3, 3]) @ rot_wc.T  # [k, 3]
    z = t_cam[:, 2]
    in_front = z > near
    z_safe = jnp.where(in_front, z, 1.0)  # keeps culled rows finite (and their gradients)
    tan_xy = t_cam[:, :2] / z_safe[:, None]  # [k, 2] x/z, y/z
    lo, hi = frustum_tangents(fx, fy, cx, cy, width, height)
    in_band = jnp.all((tan_xy >= FRUSTUM_CULL * lo) & (tan_xy <= FRUSTUM_CULL * hi), axis=1)
    focal = jnp.stack([fx, fy]).astype(z.dtype)
    uv = focal * tan_xy + jnp.stack([cx, cy]).astype(z.dtype)
    x_over_z, y_over_z = jnp.clip(tan_xy, FRUSTUM_CLAMP * lo, FRUSTUM_CLAMP * hi).T
    zero = jnp.zeros_like(z)
    jac = jnp.stack([fx / z_safe, zero, -fx * x_over_z / z_safe,
                     zero, fy / z_safe, -fy * y_over_z / z_safe], -1).reshape(-1, 2, 3)
    m = jac @ rot_wc  # [k, 2, 3]
    cov2 = m @ splats.covs @ jnp.swapaxes(m, -1, -2)  # [k, 2, 2]
    a, b, c = cov2[:, 0, 0] + blur, cov2[:, 0, 1], cov2[:, 1, 1] + blur
    det = a * c - b * b
    conic = jnp.stack([c / det, -b / det, a / det], axis=-1)
    bounded = jnp.maximum(a, c) <= (MAX_FOOTPRINT * max(width, height)) ** 2
    visible = in_front & in_band & bounded & (splats.opacities >= ALPHA_MIN)
    # Mahalanobis radius beyond which o exp(-m²/2) < ALPHA_MIN (non-differentiable).
    opac = jax.lax.stop_gradient(splats.opacities)
    m2_max = 2.0 * jnp.log(jnp.maximum(opac, ALPHA_MIN) / ALPHA_MIN)
    diag = jax.lax.stop_gradient(jnp.stack([a, c], axis=-1))
    extent = jnp.sqrt(m2_max[:, None] * diag)
    opacity = jnp.where(visible, splats.opacities, 0.0)
    return Projected(uv, conic, z, opacity, extent, visible)


def splat_alpha(pixels, uv, conic, opacity):
    """α [p, m] of m splats at p pixel centres ``pixels [p, 2]`` (clamped, small ones zeroed).

    ``α = min(ALPHA_MAX, o exp(q))`` with ``q = -½ dᵀ Σ'⁻¹ d``, then 0 where
    ``α < ALPHA_MIN``. Written for speed on CPU without changing the result:
    q is floored at POWER_FLOOR (below it α < ALPHA_MIN for any o <= 1 anyway;
    the exp of a large negative number is a subnormal float, very slow on x86),
    and the threshold is the exact step ``floor(α - ALPHA_MIN) + 1`` (0 or 1 since
    0 <= α < 1) because XLA's CPU code for compare-and-select is not vectorised.
    """
    du = pixels[:, None, 0] - uv[None, :, 0]  # [p, m]
    dv = pixels[:, None, 1] - uv[None, :, 1]
    power = -0.5 * (conic[:, 0] * du * du + conic[:, 2] * dv * dv) - conic[:, 1] * du * dv
    alpha = jnp.minimum(ALPHA_MAX, opacity * jnp.exp(jnp.maximum(power, POWER_FLOOR)))
    return alpha * jax.lax.stop_gradient(jnp.floor(alpha - ALPHA_MIN) + 1.0)


def _composite_chunk(carry, pixels, uv, conic, opacity, colour, depth):
    """Composite one depth-ordered chunk of m splats over p pixels, front to back.

    carry = (log T [p], C [p, 3], D [p]). Within the chunk
    ``log T_i = log T + Σ_{j<i} log(1 - α_j)``, the prefix sum done as a product
    with a strictly upper-triangular matrix of ones (a small matmul is faster on
    CPU than a cumulative sum).
    """
    log_trans, rgb, dep = carry
    alpha = splat_alpha(pixels, uv, conic, opacity)  # [p, m]
    log1m = jnp.log1p(-alpha)
    m = alpha.shape[1]
    strict_upper = jnp.triu(jnp.ones((m, m), alpha.dtype), k=1)  # [j, i] = 1 where j < i
    weight = alpha * transmittance(log_trans[:, None] + log1m @ strict_upper)  # α_i T_i
    return log_trans + jnp.sum(log1m, axis=1), rgb + weight @ colour, dep + weight @ depth


def transmittance(log_t):
    """T = exp(max(log T, LOG_T_MIN)): floored far below float32 resolution of any output,
    which keeps subnormal floats (very slow on CPU) out of the arithmetic."""
    return jnp.exp(jnp.maximum(log_t, LOG_T_MIN))


def _tile_pixels(tile_id, n_tiles_x, tile):
    """Pixel centres [tile², 2] as (u, v) of tile ``tile_id`` (row-major tile grid)."""
    ty, tx = tile_id // n_tiles_x, tile_id % n_tiles_x
    r, c = jnp.meshgrid(jnp.arange(tile), jnp.arange(tile), indexing="ij")
    return pixel_centre(jnp.stack([(tx * tile + c).ravel(), (ty * tile + r).ravel()], -1))


def _tile_ranges(lo, hi, n_tiles_x, n_tiles_y, tile):
    """First tile (x, y) [k, 2] and number of tiles per axis [k, 2] touched by each box.

    A box touches tile x iff ``x · tile < hi`` and ``(x + 1) · tile > lo`` (the
    tile's full pixel area, so pixel centres are covered with half a pixel to spare).
    """
    n_tiles_xy = jnp.array([n_tiles_x, n_tiles_y])
    first = jnp.floor(jnp.clip(lo / tile, -1, n_tiles_xy)).astype(jnp.int32)
    last = jnp.ceil(jnp.clip(hi / tile, -1, n_tiles_xy)).astype(jnp.int32) - 1
    first, last = jnp.maximum(first, 0), jnp.minimum(last, n_tiles_xy - 1)
    return first, jnp.maximum(last - first + 1, 0)


class TileLists(NamedTuple):
    """For every tile, its nearest overlapping splats (indices into depth-sorted order)."""

    index: jax.Array  # [t, capacity] int32 depth rank, 0 where unused
    count: jax.Array  # [t] int32 splats used by the tile (<= capacity)
    dropped: jax.Array  # [] int32 overlaps left out for lack of capacity


def tile_lists(lo, hi, visible, *, n_tiles_x, n_tiles_y, tile, capacity) -> TileLists:
    """Bin depth-sorted splat boxes ``[lo, hi]`` ([k, 2] each, px) into tiles, nearest first.

    Every (splat, tile) overlap becomes one int32 key ``tile_id · k + rank``; the
    keys go into a fixed buffer of ``t · capacity`` slots (overflow beyond it drops
    the globally farthest overlaps, counted), one sort groups them by tile and
    within a tile by depth, and each tile takes the first ``capacity`` of its run.
    Cost O(k + t · capacity · log), independent of how the overlaps are spread.
    """
    k = lo.shape[0]
    n_tiles = n_tiles_x * n_tiles_y
    if n_tiles * k >= np.iinfo(np.int32).max:
        raise ValueError(f"{k} splats x {n_tiles} tiles is too many to key in int32; use larger tiles")
    first, span = _tile_ranges(lo, hi, n_tiles_x, n_tiles_y, tile)
    n_pairs = jnp.where(visible, span[:, 0] * span[:, 1], 0)  # [k]
    ends = jnp.cumsum(n_pairs)  # [k] inclusive
    total = ends[-1]
    n_slots = min(n_tiles * capacity, n_tiles * k)
    slot = jnp.arange(n_slots, dtype=jnp.int32)
    rank = jnp.minimum(jnp.searchsorted(ends, slot, side="right"), k - 1).astype(jnp.int32)
    local = slot - (ends[rank] - n_pairs[rank])
    width = jnp.maximum(span[rank, 0], 1)
    tile_id = (first[rank, 1] + local // width) * n_tiles_x + first[rank, 0] + local % width
    keys = jnp.where(slot < total, tile_id * k + rank, np.iinfo(np.int32).max)
    keys = jnp.sort(keys)
    starts = jnp.searchsorted(keys, jnp.arange(n_tiles + 1, dtype=jnp.int32) * k)  # [t + 1]
    in_tile = jnp.diff(starts)  # [t]
    count = jnp.minimum(in_tile, capacity)
    pos = jnp.minimum(starts[:-1, None] + jnp.arange(capacity), n_slots - 1)  # [t, capacity]
    valid = jnp.arange(capacity) < count[:, None]
    index = jnp.where(valid, keys[pos] - jnp.arange(n_tiles)[:, None] * k, 0)
    dropped = jnp.sum(in_tile - count) + jnp.maximum(total - n_slots, 0)
    return TileLists(index, count, dropped.astype(jnp.int32))


@functools.partial(jax.jit, static_argnames=("width", "height", "tile", "capacity", "blur"))
def _rasterize(splats, fx, fy, cx, cy, pose, background, near, *, width, height, tile, capacity,
               blur):
    """The jitted body of :func:`rasterize` (image size, tile, capacity and blur static)."""
    proj = project(splats, fx, fy, cx, cy, pose, near, blur, width=width, height=height)
    order = jnp.argsort(jnp.where(proj.visible, proj.depth, jnp.inf))  # [k] front to back
    n_tiles_x, n_tiles_y = -(-width // tile), -(-height // tile)
    n_tiles = n_tiles_x * n_tiles_y
    lists = tile_lists(
        jax.lax.stop_gradient(proj.uv - proj.extent)[order],
        jax.lax.stop_gradient(proj.uv + proj.extent)[order],
        proj.visible[order],
        n_tiles_x=n_tiles_x, n_tiles_y=n_tiles_y, tile=tile, capacity=capacity,
    )
    # Pad each tile's list to whole chunks; padding and unused entries get opacity 0.
    chunk = min(DEPTH_CHUNK, capacity)
    n_chunks = -(-capacity // chunk)
    index = jnp.pad(lists.index, ((0, 0), (0, n_chunks * chunk - capacity)))
    idx = order[index]  # [t, c] splat ids
    used = jnp.arange(n_chunks * chunk) < lists.count[:, None]  # [t, c]

    def chunked(x):  # [t, c, ...] -> [t, n_chunks, chunk, ...]
        return x.reshape((n_tiles, n_chunks, chunk) + x.shape[2:])

    gathered = (
        chunked(proj.uv[idx]), chunked(proj.conic[idx]),
        chunked(jnp.where(used, proj.opacity[idx], 0.0)),
        chunked(splats.colours[idx]), chunked(proj.depth[idx]),
    )

    # Checkpointing per tile and per chunk keeps the backward pass's memory to the
    # chunk inputs; skipped chunks (past the tile's count) cost a branch only.
    @jax.checkpoint
    def one_tile(xs):
        tile_id, count, *chunks = xs
        pixels = _tile_pixels(tile_id, n_tiles_x, tile)

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

    log_trans, rgb, dep = jax.lax.map(one_tile, (jnp.arange(n_tiles), lists.count, *gathered))

    def to_image(x):  # [t, tile*tile, ...] -> [height, width, ...]
        x = x.reshape((n_tiles_y, n_tiles_x, tile, tile) + x.shape[2:])
        x = jnp.swapaxes(x, 1, 2).reshape((n_tiles_y * tile, n_tiles_x * tile) + x.shape[4:])
        return x[:height, :width]

    trans = transmittance(to_image(log_trans))
    rgb = to_image(rgb) + trans[..., None] * background
    return RenderOutput(rgb, to_image(dep), 1.0 - trans, lists.dropped)


def rasterize(
    splats: Splats,
    camera: Camera,
    *,
    background=(0.0, 0.0, 0.0),
    tile: int = DEFAULT_TILE,
    capacity: int = DEFAULT_CAPACITY,
    near: float = NEAR,
    blur: float = BLUR_VARIANCE,
) -> RenderOutput:
    """Render ``splats`` seen by ``camera``: rgb [h, w, 3], depth [h, w], alpha [h, w], dropped.

    Tiled and jitted: compiled once per splat count, image size, tile, capacity and
    blur. Differentiable w.r.t. the splat arrays (and intrinsics/pose); the per-tile
    choice of splats is not. If ``out.dropped > 0`` some tile had more overlapping
    splats than ``capacity`` and its farthest ones were left out: see
    :func:`check_dropped`. The camera's ``width``/``height`` must be Python ints
    (close over the camera when wrapping this in ``jax.jit``).

    background: RGB (or grey scalar) composited with T_final; tile: tile side (px);
    capacity: splats kept per tile; near: near-plane depth for culling; blur: the
    low-pass dilation variance (px²) added to every projected covariance.
    """
    width, height, background = _check_inputs(splats, camera, background, tile, capacity, blur)
    if splats.count == 0:
        return _empty(width, height, background)
    return _rasterize(
        splats, camera.fx, camera.fy, camera.cx, camera.cy, camera.pose, background, near,
        width=width, height=height, tile=int(tile), capacity=int(capacity), blur=float(blur),
    )


def surface_depth(out: RenderOutput, min_alpha: float = SURFACE_ALPHA) -> np.ndarray:
    """Depth of the visible surface ``[h, w]``: the expected depth over the covered
    fraction, ``D / alpha``, where ``alpha > min_alpha``; 0 (no surface) elsewhere."""
    alpha = np.asarray(out.alpha)
    return np.where(alpha > min_alpha, np.asarray(out.depth) / np.maximum(alpha, 1e-6), 0.0)


def check_dropped(out: RenderOutput) -> RenderOutput:
    """Raise ``RuntimeError`` if any splat was dropped for lack of tile capacity; else return ``out``."""
    n = int(out.dropped)
    if n:
        raise RuntimeError(
            f"{n} splat-tile overlaps were dropped for lack of capacity; "
            "render again with a larger `capacity` or a smaller `tile`"
        )
    return out


def required_capacity(
    splats: Splats, camera: Camera, *, tile: int = DEFAULT_TILE, near: float = NEAR,
    blur: float = BLUR_VARIANCE,
) -> int:
    """The largest number of splats overlapping one tile: the ``capacity`` at which
    :func:`rasterize` drops nothing for this view. Cheap (O(k + tiles)); not traceable."""
    width, height, _ = _check_inputs(splats, camera, 0.0, tile, 1, blur)
    if splats.count == 0:
        return 0
    counts = _tile_counts(splats, camera.fx, camera.fy, camera.cx, camera.cy, camera.pose, near,
                          width=width, height=height, tile=int(tile), blur=float(blur))
    return int(counts.max())


def exact_capacity(splats: Splats, camera: Camera, *, tile: int = DEFAULT_TILE,
                   near: float = NEAR, blur: float = BLUR_VARIANCE) -> int:
    """A ``capacity`` at which :func:`rasterize` drops nothing for this view: the
    :func:`required_capacity` rounded up to a power of two and at least
    DEFAULT_CAPACITY, so that renders of similar views share a few compiled sizes."""
    need = required_capacity(splats, camera, tile=tile, near=near, blur=blur)
    return max(DEFAULT_CAPACITY, 1 << max(0, need - 1).bit_length())


@functools.partial(jax.jit, static_argnames=("width", "height", "tile", "blur"))
def _tile_counts(splats, fx, fy, cx, cy, pose, near, *, width, height, tile, blur):
    """Overlapping splats per tile [ty, tx], by a 2-D difference array and two cumsums."""
    proj = project(splats, fx, fy, cx, cy, pose, near, blur, width=width, height=height)
    n_tiles_x, n_tiles_y = -(-width // tile), -(-height // tile)
    first, span = _tile_ranges(proj.uv - proj.extent, proj.uv + proj.extent, n_tiles_x,
                               n_tiles_y, tile)
    end = first + span
    weight = (proj.visible & jnp.all(span > 0, axis=1)).astype(jnp.int32)
    diff = jnp.zeros((n_tiles_y + 1, n_tiles_x + 1), jnp.int32)
    for y, x, sign in ((first[:, 1], first[:, 0], 1), (first[:, 1], end[:, 0], -1),
                       (end[:, 1], first[:, 0], -1), (end[:, 1], end[:, 0], 1)):
        diff = diff.at[y, x].add(sign * weight)
    return jnp.cumsum(jnp.cumsum(diff, axis=0), axis=1)[:n_tiles_y, :n_tiles_x]


def _check_inputs(splats, camera, background, tile, capacity, blur=BLUR_VARIANCE):
    """Validate arguments; return static (width, height) and background as a [3] array."""
    check_splats(splats)
    if not isinstance(camera, Camera):
        raise TypeError(f"camera must be a vbgs.camera.Camera, got {type(camera).__name__}")
    try:
        width, height = int(camera.width), int(camera.height)
    except (TypeError, jax.errors.ConcretizationTypeError) as err:
        raise TypeError(
            "camera.width and camera.height must be static Python ints; close over the camera "
            "instead of passing it through jax.jit as an argument"
        ) from err
    if width <= 0 or height <= 0:
        raise ValueError(f"camera size must be positive, got {width}x{height}")
    if np.shape(camera.pose) != (4, 4):
        raise ValueError(f"camera.pose must be [4, 4], got shape {np.shape(camera.pose)}")
    if int(tile) <= 0 or int(capacity) <= 0:
        raise ValueError(f"tile and capacity must be positive, got {tile} and {capacity}")
    if not float(blur) >= 0:
        raise ValueError(f"blur is a variance in px² and must be >= 0, got {blur}")
    background = jnp.asarray(background, splats.means.dtype)
    if background.shape not in ((), (3,)):
        raise ValueError(f"background must be a scalar or an RGB triple, got shape {background.shape}")
    return width, height, jnp.broadcast_to(background, (3,))


def _empty(width, height, background) -> RenderOutput:
    """The render of no splats: background everywhere, zero depth and alpha."""
    zeros = jnp.zeros((height, width), background.dtype)
    rgb = jnp.broadcast_to(background, (height, width, 3))
    return RenderOutput(rgb, zeros, zeros, jnp.zeros((), jnp.int32))
