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

* **near the camera**: splats whose depth is within ``NEAR_SIGMAS`` (1) of their own
  spread (``z² <= NEAR_SIGMAS² tr Σ``: the camera inside the splat's one-sigma ball) are
  culled, and so is every splat at ``z <= near`` (default ``NEAR`` = 0: none in front
  of the camera); close to the camera the linearisation behind J breaks down, and how
  close is relative to the splat, not a length in scene units (3DGS's fixed 0.2 units
  culled the whole of a scene given in kilometres).
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
equals :func:`vbgs.render.raster_reference.render_reference` whenever nothing is dropped. Each tile keeps the
``capacity`` nearest overlapping splats; the rest (the farthest) are *dropped*
and counted in ``RenderOutput.dropped`` (once per splat and tile). Check it, e.g.
``assert int(out.dropped) == 0`` or call :func:`check_dropped`, and raise
``capacity`` (or lower ``tile``) if it is not zero; :func:`required_capacity`
gives the smallest capacity that drops nothing for a given view.

Implementation (chosen by measurement on a 2-core CPU, see
``experiments/benchmarks/bench_raster.py``): one depth sort of the splats; one int32 sort of
(tile, depth rank) keys gives every tile its nearest ``capacity`` splats
(:func:`tile_lists`); then ``lax.map`` over tiles and ``lax.scan`` over chunks of
DEPTH_CHUNK splats, where a ``lax.cond`` skips the chunks past the tile's count,
so the compositing cost follows the actual overlaps rather than the capacity.
That compositing loop (:func:`vbgs.render.composite.composite_tiles`, the "xla" impl, with
the compositing formulas of this docstring) has a Pallas twin for GPUs
(:mod:`vbgs.render.raster_pallas`, the "pallas" impl) over the same tile lists; ``rasterize(impl="auto")`` takes it on a GPU backend (see
:func:`resolve_impl`). The projection's and the XLA compositing's matrix products run
at full float32 precision (:mod:`vbgs.inference.precision`), so TF32 on NVIDIA GPUs changes
nothing; the Pallas kernel has none (elementwise sums only).
"""

from __future__ import annotations

import functools
import os
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.precision import matmul
from vbgs.render.camera import Camera
from vbgs.render.composite import (  # noqa: F401 (ALPHA_MAX, DEPTH_CHUNK: re-exported, the spec's constants)
    ALPHA_MAX,
    ALPHA_MIN,
    DEPTH_CHUNK,
    TileSplats,
    composite_tiles,
    transmittance,
)
from vbgs.render.raster_pallas import composite_tiles_pallas
from vbgs.render.splats import Splats, check_splats

BLUR_VARIANCE = 0.3  # px², low-pass dilation added to every projected covariance
DEFAULT_TILE = 16  # tile side in pixels (measured best of 8/16/32 on a 2-core CPU)
DEFAULT_CAPACITY = 2048  # splats kept per tile, nearest first (8 per pixel at tile 16)
NEAR = 0.0  # default fixed near plane (scene units, camera z): none besides z > 0
NEAR_SIGMAS = 1.0  # splats with z <= NEAR_SIGMAS * sqrt(tr Σ) are culled (scale-free)
FRUSTUM_CLAMP = 1.3  # J is evaluated with x/z, y/z clamped to 1.3x the frustum extent (3DGS)
FRUSTUM_CULL = 2.0  # means beyond 2x the frustum extent are culled (guard band beyond the clamp)
MAX_FOOTPRINT = 1.0  # splats whose projected sigma exceeds 1 image size (longer side) are culled
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
    t_cam = matmul(splats.means - pose[:3, 3], rot_wc.T)  # [k, 3]
    z = t_cam[:, 2]
    spread = jnp.trace(splats.covs, axis1=-2, axis2=-1)  # [k] tr Σ, the one-sigma ball²
    in_front = (z > near) & (z * z > NEAR_SIGMAS**2 * spread)
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
    m = matmul(jac, rot_wc)  # [k, 2, 3]
    cov2 = matmul(matmul(m, splats.covs), jnp.swapaxes(m, -1, -2))  # [k, 2, 2]
    a, b, c = cov2[:, 0, 0] + blur, cov2[:, 0, 1], cov2[:, 1, 1] + blur
    det = a * c - b * b
    conic = jnp.stack([c / det, -b / det, a / det], axis=-1)
    bounded = jnp.maximum(a, c) <= (MAX_FOOTPRINT * max(width, height)) ** 2
    # a covariance that came out indefinite in float32 (posterior assignment can leave one
    # so: room, --assign posterior, frame 53) projects to no ellipse: it is drawn nowhere
    # and gets no opacity evidence (vbgs.render.opacity)
    det_conic = conic[:, 0] * conic[:, 2] - conic[:, 1] ** 2
    ellipse = (det > 0.0) & (a > 0.0) & (c > 0.0) & jnp.isfinite(det_conic) & (det_conic > 0.0)
    visible = in_front & in_band & bounded & ellipse & (splats.opacities >= ALPHA_MIN)
    # Mahalanobis radius beyond which o exp(-m²/2) < ALPHA_MIN (non-differentiable).
    opac = jax.lax.stop_gradient(splats.opacities)
    m2_max = 2.0 * jnp.log(jnp.maximum(opac, ALPHA_MIN) / ALPHA_MIN)
    diag = jax.lax.stop_gradient(jnp.stack([a, c], axis=-1))
    extent = jnp.sqrt(m2_max[:, None] * diag)
    opacity = jnp.where(visible, splats.opacities, 0.0)
    return Projected(uv, conic, z, opacity, extent, visible)


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


def tile_splats(splats, proj: Projected, *, width, height, tile, capacity):
    """Depth-sort the projected splats, bin them into tiles (:func:`tile_lists`) and gather
    each tile's parameters: ``(TileSplats, dropped)``. Differentiable w.r.t. the gathered
    values (the choice of splats is not)."""
    order = jnp.argsort(jnp.where(proj.visible, proj.depth, jnp.inf))  # [k] front to back
    n_tiles_x, n_tiles_y = -(-width // tile), -(-height // tile)
    lists = tile_lists(
        jax.lax.stop_gradient(proj.uv - proj.extent)[order],
        jax.lax.stop_gradient(proj.uv + proj.extent)[order],
        proj.visible[order],
        n_tiles_x=n_tiles_x, n_tiles_y=n_tiles_y, tile=tile, capacity=capacity,
    )
    idx = order[lists.index]  # [t, c] splat ids
    used = jnp.arange(capacity) < lists.count[:, None]  # [t, c]
    gathered = TileSplats(
        proj.uv[idx], proj.conic[idx], jnp.where(used, proj.opacity[idx], 0.0),
        splats.colours[idx], proj.depth[idx], lists.count,
    )
    return gathered, lists.dropped


@functools.partial(jax.jit, static_argnames=("width", "height", "tile", "capacity", "blur",
                                             "impl", "interpret"))
def _rasterize(splats, fx, fy, cx, cy, pose, background, near, *, width, height, tile, capacity,
               blur, impl="xla", interpret=False):
    """The jitted body of :func:`rasterize` (image size, tile, capacity, blur and the
    resolved ``impl``, "xla" or "pallas", static; ``interpret``: Pallas interpret mode)."""
    proj = project(splats, fx, fy, cx, cy, pose, near, blur, width=width, height=height)
    tiles, dropped = tile_splats(splats, proj, width=width, height=height, tile=tile,
                                 capacity=capacity)
    n_tiles_x, n_tiles_y = -(-width // tile), -(-height // tile)
    if impl == "pallas":
        log_trans, rgb, dep = composite_tiles_pallas(tiles, n_tiles_x=n_tiles_x, tile=tile,
                                                     interpret=interpret)
    else:
        log_trans, rgb, dep = composite_tiles(tiles, n_tiles_x=n_tiles_x, tile=tile)

    def to_image(x):  # [t, tile*tile, ...] -> [height, width, ...]
        x = x.reshape((n_tiles_y, n_tiles_x, tile, tile) + x.shape[2:])
        x = jnp.swapaxes(x, 1, 2).reshape((n_tiles_y * tile, n_tiles_x * tile) + x.shape[4:])
        return x[:height, :width]

    trans = transmittance(to_image(log_trans))
    rgb = to_image(rgb) + trans[..., None] * background
    return RenderOutput(rgb, to_image(dep), 1.0 - trans, dropped)


IMPLS = ("auto", "xla", "pallas")
IMPL_ENV = "VBGS_RASTER_IMPL"  # overrides impl="auto" when set


def resolve_impl(impl: str, tile: int) -> tuple[str, bool]:
    """``(impl, interpret)`` actually used for ``impl`` in IMPLS: "auto" reads the
    VBGS_RASTER_IMPL environment variable if set, else takes "pallas" on a GPU backend
    (when ``tile`` is a power of two, as Triton blocks need) and "xla" otherwise.
    Pallas off a GPU runs in interpret mode (slow; for tests)."""
    if impl not in IMPLS:
        raise ValueError(f"impl must be one of {', '.join(IMPLS)}, got {impl!r}")
    if impl == "auto" and os.environ.get(IMPL_ENV):
        impl = os.environ[IMPL_ENV]
        if impl not in IMPLS:
            raise ValueError(f"{IMPL_ENV} must be one of {', '.join(IMPLS)}, got {impl!r}; "
                             "unset it or fix its value")
    gpu = jax.default_backend() == "gpu"
    power_of_two = tile > 0 and tile & (tile - 1) == 0
    if impl == "auto":
        impl = "pallas" if gpu and power_of_two else "xla"
    if impl == "pallas" and not power_of_two:
        raise ValueError(f"impl='pallas' needs a power-of-two tile (8, 16, 32), got {tile}; "
                         "pass such a tile or impl='xla'")
    return impl, impl == "pallas" and not gpu


def rasterize(
    splats: Splats,
    camera: Camera,
    *,
    background=(0.0, 0.0, 0.0),
    tile: int = DEFAULT_TILE,
    capacity: int = DEFAULT_CAPACITY,
    near: float = NEAR,
    blur: float = BLUR_VARIANCE,
    impl: str = "auto",
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
    low-pass dilation variance (px²) added to every projected covariance; impl: the
    compositing code, "xla" (lax.map over tiles), "pallas" (:mod:`vbgs.render.raster_pallas`,
    interpret mode off a GPU) or "auto" (see :func:`resolve_impl`: pallas on a GPU, xla
    otherwise, VBGS_RASTER_IMPL overrides). Both give the same render and gradients.
    """
    width, height, background = _check_inputs(splats, camera, background, tile, capacity, blur)
    impl, interpret = resolve_impl(impl, int(tile))
    if splats.count == 0:
        return _empty(width, height, background)
    return _rasterize(
        splats, camera.fx, camera.fy, camera.cx, camera.cy, camera.pose, background, near,
        width=width, height=height, tile=int(tile), capacity=int(capacity), blur=float(blur),
        impl=impl, interpret=interpret,
    )


def visible_surface(depth_sum, alpha, min_alpha: float = SURFACE_ALPHA):
    """The one definition of the alpha-normalised depth: ``(depth [h, w], covered [h, w])``,
    the expected depth over the covered fraction ``D / alpha`` where ``alpha > min_alpha``
    (``covered``; the test sees no gradient), 0 (no surface) elsewhere. Scoring
    (:func:`surface_depth`) and the gradient baseline's depth loss both use it."""
    covered = jax.lax.stop_gradient(alpha) > min_alpha
    return jnp.where(covered, depth_sum / jnp.where(covered, alpha, 1.0), 0.0), covered


def surface_depth(out: RenderOutput, min_alpha: float = SURFACE_ALPHA) -> np.ndarray:
    """Depth of the visible surface ``[h, w]`` of a render (:func:`visible_surface`)."""
    return np.asarray(visible_surface(out.depth, out.alpha, min_alpha)[0])


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
        raise TypeError(f"camera must be a vbgs.render.camera.Camera, got {type(camera).__name__}")
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
