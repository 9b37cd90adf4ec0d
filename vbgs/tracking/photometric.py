"""Photometric pose refinement: the pose at which the map's splats, rendered, look most
like the frame.

Why: the geometric tracker (:mod:`vbgs.tracking.register`) fits the frame's depth
points to the map; where the depth sees one plane only (the walk under a Kinect, whose
range of 0.4-4.5 m keeps only the near road) motion along the plane is unconstrained.
The frame's colours are complete, and the splats rendered at a candidate pose
(:func:`vbgs.render.raster.rasterize`'s differentiable body) say where each colour
edge should be: the photometric error fixes what the depth leaves free.

The cost, at pose ``T exp(xi)`` (a right perturbation, the camera's own frame, as
:mod:`vbgs.tracking.se3`), over the pixels the map covers (rendered ``alpha >
min_alpha`` at the current pose; a pixel the map has not seen says nothing):

* colour: per pixel ``s_c = sum_ch (C_ch(xi) - I_ch)^2 / sigma_c^2``, ``sigma_c`` the
  colour noise (``colour_noise``);
* depth (optional, where the frame has a reading and its standard deviation
  ``sigma_d > 0`` is given): ``s_d = (D(xi) / alpha - d)^2 / sigma_d^2``, the rendered
  surface depth (:func:`vbgs.render.raster.visible_surface`'s formula) against the
  reading, weighted by the sensor's ``1 / sigma_d^2``;
* each term robust by Cauchy, ``(c^2 / 2) log(1 + s / c^2)`` with ``c`` = ``robust``
  (units of sigma): occluders, moving objects, the sky, and splats whose colour is
  wrong weigh ``1 / (1 + s / c^2)`` (IRLS weights, fixed within a Gauss-Newton step);
* a pixel where the frame has a surface (valid depth) that the map leaves uncovered
  costs what a residual at the Cauchy scale does, ``rho(c^2) = (c^2 / 2) log 2``: the
  map claims that surface and fails to show it. Without this term a pose wins by
  showing less of the map (a cost per covered pixel did: on the walk under a Kinect
  the second frame's search chose the pose 0.55 units *behind* the first, where the
  map's near ground shrinks to a few blurred rows); pixels with no surface (the sky,
  ground beyond the sensor's range) cost nothing either way.

Solver: Levenberg-Marquardt on the Gauss-Newton normal equations ``(J^T W J + lambda
diag) delta = -J^T W r``, ``J`` the residuals' Jacobian in the 6 twist coordinates by
forward mode (``jax.jacfwd``: 6 tangents cost about one render each, where reverse
mode would need one backward pass per residual or a VJP per row; the rasterizer's tile
lists are integer work with no tangent). ``J`` is taken at ``xi = 0`` of ``T (I +
hat(xi))``, the exponential's first order, whose derivative at 0 is exactly
``se3_exp``'s (``se3_exp`` itself has a ``sqrt(|w|^2)`` whose forward derivative at 0
is 0/0); the step is applied with the true exponential. A step is kept only if it
lowers the cost (each evaluation renders once with its Jacobian, so a refused step
costs one render), as the geometric tracker does.

Coarse to fine: each level renders ``widths[i]`` px wide, ``1/s`` of the frame's size
for a whole factor ``s`` (pixel centres sit at ``index + 0.5``, :mod:`vbgs.render.pixels`,
so a block of ``s x s`` pixels is one pixel of the camera with ``fx / s, fy / s, cx /
s, cy / s``), with the pixel filter that the block mean implies (:func:`level_blur`),
against the frame's colours averaged over the same blocks (and its depth where the
whole block has a reading). Coarse renders are cheap and blur the colour edges, which
widens the basin; on a young map built from a sensor's quantised depth they are also
the more accurate ones (:data:`WIDTHS`).

Search (:func:`search`): the same cost at each of a set of candidate poses, rendered
``search_width`` px wide without a Jacobian: a start where no motion guess is near.

Uncertainty: ``sqrt(diag(H^-1))`` of the final normal equations (a Laplace
approximation in units of the noise; pixels are far from independent, so it is
optimistic, as the geometric tracker's).

Precision (float32 throughout): the render is the rasterizer's (its products at full
float32 precision, :mod:`vbgs.inference.precision`); residuals are differences of
values in [0, 1] (colour) or of depths of a few units (resolution ~1e-7 relative);
``J^T W J`` and ``J^T W r`` sum ~10^4 rows in float32 at ``Precision.HIGHEST`` (a
relative error ~1e-6 sqrt(n), far below the damping); the 6x6 system is solved by a
Cholesky factorisation after damping (the translation and rotation columns differ in
scale by the scene's depth, which the diagonal damping absorbs).

Status (measured on the walk, 64 px unless said; experiments.tasks.tracking.PHOTOMETRIC):
on a synthetic textured ground plane an 8 cm, 1.5 degree offset along it is recovered
to 1e-5 units; against VBGS maps it is not accurate yet. From odometry guesses (1 cm a
frame) with exact depth, refined at 32 then 64 px, the track's ATE was 12.8 cm where
the geometric tracker alone keeps ~2 mm (15.4 cm without the uncovered term; colour
divided by the rendered alpha instead of composited over the background, 1.41 against
1.71 units under a Kinect, but 1.6 mm instead of 1e-5 on the synthetic plane). The
refinement's own minimum is off the true pose: on the walk's 12th frame (exact depth,
the map of the 11 before) started at the true pose it moved 3.2 cm (2.8 cm at 32 px,
5.0 cm without the Cauchy weights) to a pose its cost prefers (10215 against 10449),
the same with 4 times the tile capacity; the map rendered at the true pose differs
from the frame by a mean squared error of 0.028 (15.5 dB). Left: a residual model
that such a map's errors do not bias (e.g. weights from the splats' evidence, or
colour edges only), or a fusion with the geometric tracker's Hessian that lets the
colours move only what the depth leaves free.

One compiled solver per image size, tile, capacity, iteration count and splat count
(a map that keeps every slot, ``drop_unused=False``, has a fixed count).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.render.camera import Camera, valid_depth
from vbgs.render.raster import BLUR_VARIANCE, NEAR, _rasterize
from vbgs.render.splats import Splats, check_splats
# the initial Levenberg-Marquardt damping (relative to the Hessian's diagonal) and its
# factors on a refused / kept step: the geometric tracker's
from vbgs.tracking.register import DAMP_DOWN, DAMP_UP, DAMPING
from vbgs.tracking.se3 import compose, from_rt, hat, orthonormalise, se3_exp

# The levels' widths (px), coarse to fine (each level renders at the frame's width over
# the nearest whole factor, at least 1), and the Levenberg-Marquardt evaluations at
# each. Chosen on the walk's training stream under a Kinect (64 px), its second frame
# from the search's start 0.143 units off: one level 16 px wide left it 0.065 off,
# (16, 32) 0.28, (32, 64) 0.23, (16, 32, 64) 0.33 (finer renders of a young map fall
# apart into the bands of the sensor's quantised depth: more pixels, worse poses).
WIDTHS = (16,)
ITERATIONS = (8,)
# The width (px) the search (:func:`search`) renders its candidates at: on the walk's
# training stream under a Kinect (64 px), the second frame's grid search at 16 px
# picked the grid pose next to the truth (0.14 units off, the grid step 0.25), at
# 32 px one 0.8 units off (finer renders of a map one frame old fall apart into the
# bands of the sensor's quantised depth).
SEARCH_WIDTH = 16
# Colour noise sigma_c (linear RGB): the spread of a splat's colour about the pixels
# it explains; the E-step's colour noise scale (vbgs.inference.model.PriorConfig).
COLOUR_NOISE = 0.05
# Cauchy scale c in units of sigma (as the geometric tracker's ROBUST).
ROBUST = 3.0
# A pixel counts where the splats cover it this much (the rasterizer's SURFACE_ALPHA).
MIN_ALPHA = 0.5
# Tile side and splats kept per tile (nearest first): small tiles keep each tile's list
# short at the coarse level, where one tile spans a large part of the view; overlaps
# beyond the capacity (the farthest, mostly hidden) are left out of the tracking render.
TILE, CAPACITY = 8, 1024


@dataclass(frozen=True)
class PhotoConfig:
    """The refinement's settings (module docstring; defaults are the named constants)."""

    widths: tuple[int, ...] = WIDTHS
    iterations: tuple[int, ...] = ITERATIONS
    colour_noise: float = COLOUR_NOISE
    robust: float = ROBUST
    min_alpha: float = MIN_ALPHA
    damping: float = DAMPING
    # the depth term (module docstring) is off: on the walk's training stream under a
    # Kinect the second frame's search with it picked a pose 1.3 units off (without it,
    # 0.14): the map's rendered depth, one frame old, is banded by the sensor's
    # quantisation far beyond the sigma_z of its noise model; the geometric
    # registration has used the depth already
    depth: bool = False
    search_width: int = SEARCH_WIDTH
    uncovered: bool = True  # a measured pixel the map leaves uncovered costs rho(c^2)
    tile: int = TILE
    capacity: int = CAPACITY

    def __post_init__(self):
        if not self.widths or len(self.widths) != len(self.iterations):
            raise ValueError(f"photometric refinement needs one iteration count per level, "
                             f"got widths {self.widths} and iterations {self.iterations}")
        if (any(int(s) < 1 for s in (*self.widths, self.search_width))
                or any(int(n) < 1 for n in self.iterations)):
            raise ValueError(f"photometric widths and iterations must be at least 1, got "
                             f"{self.widths}, {self.search_width} and {self.iterations}")
        if not (self.colour_noise > 0 and self.robust > 0 and self.damping > 0
                and 0 <= self.min_alpha < 1):
            raise ValueError(f"photometric colour_noise, robust and damping must be > 0 and "
                             f"min_alpha in [0, 1), got {self.colour_noise}, {self.robust}, "
                             f"{self.damping}, {self.min_alpha}")
        if int(self.tile) < 1 or int(self.capacity) < 1:
            raise ValueError(f"photometric tile and capacity must be positive, got "
                             f"{self.tile} and {self.capacity}")


class Refinement(NamedTuple):
    """A pose refined photometrically and how sure it is."""

    pose: np.ndarray  # [4, 4] camera-to-world, float64
    sigma_t: np.ndarray  # [3] standard deviations of the translation (scene units)
    sigma_r_deg: np.ndarray  # [3] of the rotation (degrees), in the camera frame
    covered: float  # share of the final level's pixels the map covers
    cost: float  # the final level's robust cost (module docstring)


def scale_for(width: int, level_width: int) -> int:
    """The whole downsampling factor that brings a frame ``width`` px wide nearest to
    ``level_width`` px (at least 1)."""
    return max(1, int(round(int(width) / int(level_width))))


def level_camera(camera: Camera, scale: int) -> Camera:
    """``camera`` seen at ``1/scale`` of its size: blocks of ``scale x scale`` pixels
    become one (module docstring); the size is rounded down."""
    s = float(scale)
    return camera._replace(width=int(camera.width) // scale, height=int(camera.height) // scale,
                           fx=camera.fx / s, fy=camera.fy / s, cx=camera.cx / s,
                           cy=camera.cy / s)


def level_blur(blur: float, scale: int) -> float:
    """The pixel filter (coarse px^2) that renders at ``1/scale`` what the map's filter
    ``blur`` (fine px^2) followed by the ``scale x scale`` block mean draws: variances
    add, the fine filter's is ``blur / scale^2`` coarse px^2 and the block's (a box
    of ``scale`` fine pixels, less the fine pixel's own) ``(scale^2 - 1) / (12 scale^2)``
    per axis. The map's own filter at the coarse size, ``blur`` coarse px^2, widens
    every thin splat ``scale`` times too much: the ground near the horizon then covers
    more than the frame shows, and the pitch came out 1.9 (scale 2) and 5.8 degrees
    (scale 4) off on a synthetic ground plane that the full size recovers exactly."""
    s2 = float(scale) ** 2
    return float(blur) / s2 + (s2 - 1.0) / (12.0 * s2)


def pool(image: np.ndarray, scale: int) -> np.ndarray:
    """Block means of ``image [h, w, ...]`` over ``scale x scale`` blocks (the rows and
    columns past a whole block dropped)."""
    h, w = image.shape[0] // scale, image.shape[1] // scale
    x = np.asarray(image, np.float64)[: h * scale, : w * scale]
    # a sum of the blocks' strided planes: numpy's mean over the reshaped block axes
    # reduces along non-contiguous axes, 4 times slower (a tracked frame pools 3 levels)
    total = sum(x[i::scale, j::scale] for i in range(scale) for j in range(scale))
    return total / float(scale * scale)


def pool_depth(depth: np.ndarray, sigma: np.ndarray | None, scale: int):
    """Block means of a depth map and its standard deviations, a block kept only where
    every pixel has a reading (0 elsewhere); the block's sigma is its pixels' mean (the
    readings' errors are correlated over a few pixels: averaging is not counted as
    lowering the noise). ``sigma`` None: the depth alone (every reading counts), and
    None for the sigmas."""
    ok = valid_depth(depth)
    if sigma is not None:
        ok &= np.isfinite(sigma) & (sigma > 0)
    full = pool(ok.astype(np.float64), scale) >= 1.0
    d = np.where(full, pool(np.where(ok, depth, 0.0), scale), 0.0)
    if sigma is None:
        return d, None
    return d, np.where(full, pool(np.where(ok, sigma, 0.0), scale), 0.0)


def _cauchy(s, c):
    """Cauchy's cost of squared normalised residuals ``s`` and its IRLS weight."""
    return 0.5 * c * c * jnp.log1p(s / (c * c)), 1.0 / (1.0 + s / (c * c))


class _Level(NamedTuple):
    """One level's frame: ``rgb [h, w, 3]``, ``depth [h, w]`` and its ``inv_sigma [h,
    w]`` (0: no reading), the coarse camera's ``intrinsics`` (fx, fy, cx, cy) and the
    render's ``background [3]``."""

    intrinsics: jax.Array
    rgb: jax.Array
    depth: jax.Array
    inv_sigma: jax.Array
    measured: jax.Array  # [h, w] bool: the frame has a surface there (valid depth)
    uncovered: jax.Array  # [] 1.0: an uncovered measured pixel costs (module docstring)
    background: jax.Array


STATIC = ("width", "height", "tile", "capacity", "blur")


def _residuals(splats, level: _Level, pose, xi, colour_noise, min_alpha, near, *, width,
               height, tile, capacity, blur):
    """Normalised residuals ``[3 h w + h w]`` (colour, then depth) at ``pose (I +
    hat(xi))`` and the covered pixels ``[h, w]`` (module docstring)."""
    fx, fy, cx, cy = level.intrinsics
    # the exponential's first order (module docstring): only evaluated at xi = 0
    bump = jnp.eye(4, dtype=pose.dtype) + jnp.zeros((4, 4), pose.dtype).at[:3, :3].set(
        hat(xi[3:])).at[:3, 3].set(xi[:3])
    out = _rasterize(splats, fx, fy, cx, cy, compose(pose, bump), level.background, near,
                     width=width, height=height, tile=tile, capacity=capacity, blur=blur,
                     impl="xla")
    covered = jax.lax.stop_gradient(out.alpha) > min_alpha
    surface = out.depth / jnp.where(covered, out.alpha, 1.0)
    rc = jnp.where(covered[..., None], (out.rgb - level.rgb) / colour_noise, 0.0)
    rd = jnp.where(covered & (level.inv_sigma > 0), (surface - level.depth) * level.inv_sigma,
                   0.0)
    r = jnp.concatenate([rc.reshape(-1), rd.reshape(-1)])
    return r, covered, jnp.sum(level.measured & ~covered) * level.uncovered


def _robust(r, covered, missed, robust):
    """The cost (module docstring: covered pixels' Cauchy terms plus ``rho(c^2)`` for
    each measured pixel the map leaves uncovered), the residuals' IRLS weights and the
    covered count."""
    n_pix = covered.size
    rho_c, w_c = _cauchy(jnp.sum(r[: 3 * n_pix].reshape(n_pix, 3) ** 2, -1), robust)
    rho_d, w_d = _cauchy(r[3 * n_pix:] ** 2, robust)
    outlier = _cauchy(robust * robust, robust)[0]
    cost = jnp.sum(rho_c) + jnp.sum(rho_d) + outlier * missed
    return cost, jnp.concatenate([jnp.repeat(w_c, 3), w_d]), jnp.sum(covered)


@partial(jax.jit, static_argnames=STATIC)
def _costs(splats, level: _Level, poses, colour_noise, robust, min_alpha, near, **static):
    """The robust cost ``[m]`` at each of ``poses [m, 4, 4]`` (inf where nothing is
    covered), one render each."""
    def one(pose):
        r, covered, missed = _residuals(splats, level, pose, jnp.zeros(6, pose.dtype),
                                        colour_noise, min_alpha, near, **static)
        cost, _, n_cov = _robust(r, covered, missed, robust)
        return jnp.where(n_cov > 0, cost, jnp.inf)

    return jax.lax.map(one, poses)


@partial(jax.jit, static_argnames=STATIC + ("iterations",))
def _solve(splats, level: _Level, pose, colour_noise, robust, min_alpha, damping, near, *,
           iterations, **static):
    """Levenberg-Marquardt at one level: the final pose, cost, Hessian and covered share."""
    hp = jax.lax.Precision.HIGHEST

    def residuals(xi, base):
        r, covered, missed = _residuals(splats, level, base, xi, colour_noise, min_alpha,
                                        near, **static)
        return r, (r, covered, missed)

    def linearise(rot, t):
        jac, (r, covered, missed) = jax.jacfwd(residuals, has_aux=True)(
            jnp.zeros(6, pose.dtype), from_rt(rot, t))
        cost, w, n_cov = _robust(r, covered, missed, robust)
        wj = w[:, None] * jac
        return (cost, jnp.matmul(wj.T, r, precision=hp), jnp.matmul(wj.T, jac, precision=hp),
                n_cov)

    def body(_, carry):
        # evaluate the pose tried; keep it if it lowers the cost (the first always: the
        # start); the damped step from the pose kept is the next try
        rot, t, cost, g, h, n_cov, lam, tried = carry
        cost2, g2, h2, n2 = linearise(tried[:3, :3], tried[:3, 3])
        better = jnp.isfinite(cost2) & (cost2 < cost) & (n2 > 0)
        keep = lambda new, old: jnp.where(better, new, old)  # noqa: E731
        rot, t, cost, g, h, n_cov = (keep(tried[:3, :3], rot), keep(tried[:3, 3], t),
                                     keep(cost2, cost), keep(g2, g), keep(h2, h),
                                     keep(n2, n_cov))
        lam = jnp.where(better, lam * DAMP_DOWN, lam * DAMP_UP)
        diag = jnp.diag(h)
        a = h + jnp.diag(lam * diag + 1e-12 * jnp.max(diag) + 1e-30)
        step = -jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(a), g)
        step = jnp.where(jnp.all(jnp.isfinite(step)), step, 0.0)
        return rot, t, cost, g, h, n_cov, lam, compose(from_rt(rot, t), se3_exp(step))

    zero = jnp.zeros((), pose.dtype)
    rot, t, cost, _, h, n_cov, _, _ = jax.lax.fori_loop(
        0, iterations + 1, body,
        (pose[:3, :3], pose[:3, 3], zero + jnp.inf, jnp.zeros(6, pose.dtype),
         jnp.zeros((6, 6), pose.dtype), jnp.zeros((), jnp.int32), zero + damping / DAMP_DOWN,
         pose))
    return from_rt(rot, t), cost, h, n_cov / (level.rgb.shape[0] * level.rgb.shape[1])


def _level(camera: Camera, rgb, depth, depth_sigma, scale: int, background, blur, config,
           dtype):
    """A level's arrays (:class:`_Level`) and its static render settings."""
    cam = level_camera(camera, scale)
    target = pool(rgb, scale)
    measured = np.zeros(target.shape[:2], bool)
    if depth is not None:
        measured = pool(valid_depth(np.asarray(depth)).astype(np.float64), scale) >= 0.5
    if depth is not None and depth_sigma is not None:
        d, sd = pool_depth(np.asarray(depth, np.float64), np.asarray(depth_sigma, np.float64),
                           scale)
        inv = np.where(sd > 0, 1.0 / np.where(sd > 0, sd, 1.0), 0.0)
    else:
        d = inv = np.zeros(target.shape[:2])
    level = _Level(jnp.asarray([cam.fx, cam.fy, cam.cx, cam.cy], dtype),
                   jnp.asarray(target, dtype), jnp.asarray(d, dtype), jnp.asarray(inv, dtype),
                   jnp.asarray(measured), jnp.asarray(float(config.uncovered), dtype),
                   jnp.broadcast_to(jnp.asarray(background, dtype), (3,)))
    static = dict(width=int(cam.width), height=int(cam.height), tile=int(config.tile),
                  capacity=int(config.capacity), blur=level_blur(blur, scale))
    return level, static


def _check(splats: Splats, camera: Camera, rgb, config: PhotoConfig, depth, depth_sigma):
    """Refuse bad input in one line each; the frame's depth to use (None: colour only)."""
    check_splats(splats)
    h, w = int(camera.height), int(camera.width)
    if np.shape(rgb) != (h, w, 3):
        raise ValueError(f"rgb must be [{h}, {w}, 3] (the camera's size), got {np.shape(rgb)}")
    if not np.all(np.isfinite(rgb)):
        raise ValueError("rgb has non-finite values: photometric refinement needs every pixel")
    if depth is not None and np.shape(depth) != (h, w):
        raise ValueError(f"depth must be [{h}, {w}], got {np.shape(depth)}")
    if depth_sigma is not None and (depth is None or np.shape(depth_sigma) != (h, w)):
        raise ValueError(f"depth_sigma needs a depth and must be [{h}, {w}], got "
                         f"{np.shape(depth_sigma)}")
    if splats.count == 0:
        raise ValueError("the map has no splats: nothing to render the pose against")
    if h < scale_for(w, min(*config.widths, config.search_width)):
        raise ValueError(f"a {w}x{h} frame is too flat for levels {config.widths} px wide")
    return depth_sigma if config.depth else None


def search(splats: Splats, camera: Camera, rgb: np.ndarray, poses,
           config: PhotoConfig = PhotoConfig(), *,
           depth: np.ndarray | None = None, depth_sigma: np.ndarray | None = None,
           background=(0.0, 0.0, 0.0), blur: float = BLUR_VARIANCE,
           near: float = NEAR) -> np.ndarray:
    """The robust photometric cost ``[m]`` (module docstring; inf where the map covers
    nothing) of the frame at each candidate pose ``poses [m, 4, 4]``, rendered at
    ``config.search_width`` px wide without a Jacobian: a start for :func:`refine`
    where no motion guess is good enough (arguments as :func:`refine`)."""
    rgb = np.asarray(rgb)
    depth_sigma = _check(splats, camera, rgb, config, depth, depth_sigma)
    scale = scale_for(camera.width, config.search_width)
    poses = np.asarray(poses, np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) == 0:
        raise ValueError(f"poses must be [m, 4, 4] with m >= 1, got {poses.shape}")
    dtype = splats.means.dtype
    level, static = _level(camera, rgb, depth, depth_sigma, int(scale), background, blur,
                           config, dtype)
    out = _costs(splats, level, jnp.asarray(orthonormalise(poses), dtype),
                 float(config.colour_noise), float(config.robust), float(config.min_alpha),
                 float(near), **static)
    return np.asarray(out, np.float64)


def refine(splats: Splats, camera: Camera, rgb: np.ndarray, guess,
           config: PhotoConfig = PhotoConfig(), *, depth: np.ndarray | None = None,
           depth_sigma: np.ndarray | None = None, background=(0.0, 0.0, 0.0),
           blur: float = BLUR_VARIANCE, near: float = NEAR) -> Refinement:
    """The pose ``[4, 4]`` (camera-to-world) at which ``splats`` rendered look most like
    the frame ``rgb [h, w, 3]`` seen by ``camera`` (its intrinsics only: its pose is
    never read), starting from ``guess [4, 4]``. ``depth [h, w]``: where the frame has
    a surface (valid depth; the uncovered-surface term); with ``depth_sigma [h, w]``
    (the sensor's standard deviation per pixel; 0 or non-finite: no reading) it adds
    the depth term (``config.depth``); ``background``, ``blur``, ``near``: as the
    map's views are rendered."""
    rgb = np.asarray(rgb)
    depth_sigma = _check(splats, camera, rgb, config, depth, depth_sigma)
    pose = orthonormalise(np.asarray(guess, np.float64))
    dtype = splats.means.dtype
    for width, iterations in zip(config.widths, config.iterations, strict=True):
        s = scale_for(camera.width, width)
        level, static = _level(camera, rgb, depth, depth_sigma, s, background, blur,
                               config, dtype)
        out, cost, hess, covered = _solve(
            splats, level, jnp.asarray(pose, dtype), float(config.colour_noise),
            float(config.robust), float(config.min_alpha), float(config.damping), float(near),
            iterations=int(iterations), **static)
        pose = orthonormalise(np.asarray(out, np.float64))
    sigma = _sigmas(np.asarray(hess, np.float64))
    return Refinement(pose, sigma[:3], np.degrees(sigma[3:]), float(covered), float(cost))


def _sigmas(h: np.ndarray) -> np.ndarray:
    """``sqrt(diag(H^-1))`` ``[6]``; inf where the Hessian leaves a direction free."""
    try:
        cov = np.linalg.inv(h)
    except np.linalg.LinAlgError:
        return np.full(6, np.inf)
    diag = np.diag(cov)
    return np.where(diag > 0, np.sqrt(np.abs(diag)), np.inf)
