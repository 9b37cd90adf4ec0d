"""Direct RGB-D odometry: the motion between two arriving frames from their pixels.

Why: the map registration (:mod:`vbgs.tracking.register`) fits the frame's depth points
to the map; where the depth sees one plane only (the walk under a Kinect, whose 4.5 m
range keeps the near road) motion along the plane is free, and a whole step (0.55
units on the walk) is beyond its basin. Two consecutive frames' colours fix it: the
previous frame's pixels with depth, moved by the candidate motion and projected into
the new frame, must land on the same colours (dense photometric odometry, in the style
of Steinbruecker et al. 2011 and Kerl et al. 2013; written here from the equations).

The cost, for the transform ``T`` taking the previous camera's frame to the new
camera's (``T = M^-1`` of the motion ``M = P_prev^-1 P_new``), over the previous
frame's pixels ``i`` with depth (camera point ``p_i``, intensity ``I_prev(i)``), each
moved to ``q_i = T p_i`` and projected to ``pi(q_i)`` in the new frame:

* intensity: ``r_i = I_new(pi(q_i)) - I_prev(i)`` (grey: the mean of the channels;
  bilinear samples);
* depth (``depth=True``), as inverse depth: ``r_d = 1 / D_new(pi(q_i)) - 1 / z(q_i)``
  where the new frame has a reading at the pixel and its four neighbours (the
  geometric term: the plane's normal and tilt where the colours are weak). Inverse
  depth, as a sensor's disparity: far readings (a plane near the horizon, hundreds of
  units away, where a depth residual's slope is enormous) weigh little;
* each term divided by its robust scale (``1.4826`` times the median absolute residual,
  re-estimated at each step) and weighted by Cauchy's ``1 / (1 + s / c^2)``, ``c`` =
  ``robust``: occlusions, pixels leaving the view and the sensor's depth bands weigh
  little; points that project outside the new frame or behind it do not count.

Solver: Levenberg-Marquardt on the Gauss-Newton normal equations in the left twist of
``T`` (``T <- exp(delta) T``: ``dq/ddelta = [I, -[q]x]``), the image gradients by
central differences (sampled bilinearly), a step kept only if it lowers the cost at
the step's scale. Coarse to fine: blocks of ``factors[i]`` pixels averaged into one
(:func:`vbgs.tracking.photometric.pool`; the camera's intrinsics divided by the factor,
:func:`vbgs.tracking.photometric.level_camera`), depth where the whole block has a
reading. A 0.55-unit step moves the near road's pixels by tens of pixels at 128 px,
a few at 16.

Fixed shapes: each level solves over the previous frame's pixels with depth, padded
(weight 0) to half the level's pixels or all of them (:func:`_padded`), so one or two
compiled solvers per level.

Uncertainty: ``H^-1`` of the final normal equations in units of the robust scales
(pixels taken as independent, so optimistic), in the motion's own twist: the new
camera's frame, as the map registration's right perturbation (``P_new exp(xi)``
moves ``T`` by ``exp(-xi)``: the same covariance).

Precision: float32 throughout. Intensities lie in [0, 1] and a residual is a
difference of two (resolution ~6e-8); depths of a few units resolve ~4e-7 units; the
6x6 normal equations sum at most ``h w`` rows (16384 at 128 px) in float32 at
``Precision.HIGHEST`` (relative error ~1e-6 sqrt(n), far below the damping) and are
solved by Cholesky after Levenberg-Marquardt damping; the pose is composed with
:func:`vbgs.tracking.se3.se3_exp` (its float32 Taylor branches) and orthonormalised on
the host in float64 between levels.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.precision import matmul
from vbgs.render.camera import Camera, camera_rays, valid_depth
from vbgs.tracking.photometric import _cauchy, level_camera, pool, pool_depth
from vbgs.tracking.register import DAMP_DOWN, DAMP_UP, DAMPING
from vbgs.tracking.se3 import inverse, orthonormalise, se3_exp

# Block sizes of the levels, coarse to fine (128 px: 16, 32, 64 px wide). The full
# resolution is left to the map registration that follows.
FACTORS = (4, 2, 1)
# Levenberg-Marquardt steps per level. Chosen on the training streams' frame-to-frame
# motions under a Kinect (128 px, 60 frames; true poses, no view's score): the walk's
# chained ATE 5.84 / 5.83 mm and the object's 36.7 / 36.3 mm with (10, 8, 6) / (6, 4,
# 3) steps at 0.065 / 0.041 s of CPU a frame; blocks (4, 2) alone left the walk at 15.6.
# Re-checked on validation trajectories (seed 1; rule: the lowest summed ATE of the nine
# tracked streams, results/tuning/tracking/tracking.md, python -m experiments.tune_tracking):
# (10, 8, 6) sums 24.95 mm against the default's 24.10, lower on four streams and higher
# on five, at more CPU a frame, so (6, 4, 3) is kept.
ITERATIONS = (6, 4, 3)
# Cauchy scale c in units of each term's robust scale.
ROBUST = 2.5
# The robust scales' floors: intensity (of [0, 1]) and inverse depth, the latter a share
# of the previous frame's median inverse depth (relative: a scene in other units tracks
# the same): exact depth matches to interpolation error only, and a scale that small lets
# the depth term's interpolation and pooling errors outweigh the colours. Chosen on the
# training streams' chained motions (128 px, 60 frames, true poses; no view's score):
# the walk with exact depth 3.7 units / 15.1 / 11.7 / 20.3 mm ATE at 1e-4 / 1e-3 / 3e-3
# / 1e-2 (1 / scene units), under a Kinect 5.8 / 5.8 / 2.8 / 8.7 mm; 3e-3 is 0.013 of
# the walk's median inverse depth (0.23 per unit). Re-checked on validation trajectories
# (seed 1; rule: the lowest summed ATE of the nine tracked streams): 0.0043 (1e-3 per
# unit on the walk) sums 31.86 mm against the default's 24.10, worse on the walk under a
# Kinect though a little better on the object (results/tuning/tracking/floor_d/ against
# results/tuning/tracking/tracking.md's default row); 0.013 kept.
FLOOR_I, FLOOR_D = 1e-3, 0.013
# The MAD's factor to a Gaussian standard deviation.
MAD_SIGMA = 1.4826


@dataclass(frozen=True)
class DirectConfig:
    """The odometry's settings (module docstring; defaults are the named constants)."""

    factors: tuple[int, ...] = FACTORS
    iterations: tuple[int, ...] = ITERATIONS
    robust: float = ROBUST
    depth: bool = True
    damping: float = DAMPING

    def __post_init__(self):
        if not self.factors or len(self.factors) != len(self.iterations):
            raise ValueError(f"direct odometry needs one iteration count per level, got "
                             f"factors {self.factors} and iterations {self.iterations}")
        if any(int(f) < 1 for f in self.factors) or any(int(n) < 1 for n in self.iterations):
            raise ValueError(f"direct odometry factors and iterations must be at least 1, "
                             f"got {self.factors} and {self.iterations}")
        if not (self.robust > 0 and self.damping > 0):
            raise ValueError(f"direct odometry robust and damping must be > 0, got "
                             f"{self.robust} and {self.damping}")


class Motion(NamedTuple):
    """The motion between two frames and how sure it is."""

    motion: np.ndarray  # [4, 4] the new camera's pose in the previous camera's frame
    hessian: np.ndarray  # [6, 6] information of the new pose's right twist (v, w)
    matched: float  # share of the previous frame's depth pixels seen in the new frame
    residual: float  # the intensity's robust scale at the final level (of [0, 1])


def grey(rgb) -> np.ndarray:
    """The intensity ``[h, w]`` of ``rgb [h, w, 3]``: the channels' mean."""
    return np.asarray(rgb, np.float64).mean(-1)


def _gradient(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central differences ``d/du, d/dv`` of ``image [h, w]`` (one-sided at the border)."""
    gv, gu = np.gradient(image)
    return gu, gv


def _sample(image, x, y):
    """Bilinear samples of planes ``image [h, w, m]`` at continuous pixel indices ``x``
    (column) and ``y`` (row) ``[n]``, clamped inside; ``[n, m]``."""
    h, w = image.shape[:2]
    x0 = jnp.clip(jnp.floor(x), 0, w - 2)
    y0 = jnp.clip(jnp.floor(y), 0, h - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    i, j = y0.astype(jnp.int32), x0.astype(jnp.int32)
    return ((1 - fy) * ((1 - fx) * image[i, j] + fx * image[i, j + 1])
            + fy * ((1 - fx) * image[i + 1, j] + fx * image[i + 1, j + 1]))


# Residuals whose median sets a robust scale: every s-th of a level's rows, s the rows
# over this (a median sorts; over 16384 rows twice a step it was a third of a 128 px
# frame's odometry). Training streams' chained ATE (128 px, 60 frames, true poses, exact
# / Kinect depth; no view's score), every residual against a subsample: object 65.35 /
# 42.14 mm against 65.07 / 42.05, room 16.84 / 3.68 against 16.95 / 3.66, walk 11.72 /
# 2.78 against 11.72 / 2.89, at 44 / 22 ms of CPU a frame on the walk.
MAD_ROWS = 2048


def _mad(r, w, floor):
    """The robust scale of residuals ``r [n]`` over those with ``w > 0`` (of every
    ``n // MAD_ROWS``-th residual)."""
    step = max(1, r.shape[0] // MAD_ROWS)
    med = jnp.nanmedian(jnp.where(w > 0, jnp.abs(r), jnp.nan)[::step])
    return jnp.maximum(MAD_SIGMA * jnp.nan_to_num(med, nan=floor), floor)


def _terms(t, p, src, w, planes, k, use_depth):
    """Residuals ``[n, 2]`` (intensity, depth), their Jacobians ``[n, 2, 6]`` in the left
    twist of ``t`` and their masks ``[n, 2]``."""
    fx, fy, cx, cy = k
    q = matmul(p, t[:3, :3].T) + t[:3, 3]  # full float32: TF32 would move a still camera
    z = q[:, 2]
    zs = jnp.where(z > 1e-6, z, 1.0)
    u, v = fx * q[:, 0] / zs + cx, fy * q[:, 1] / zs + cy
    h, wd = planes.shape[:2]
    x, y = u - 0.5, v - 0.5  # pixel centres at index + 0.5
    inside = (z > 1e-6) & (x >= 0) & (y >= 0) & (x <= wd - 1) & (y <= h - 1)
    s = _sample(planes, x, y)  # intensity, d/du, d/dv, depth, d/du, d/dv, full-depth
    zero = jnp.zeros_like(z)
    # d(u, v)/dq, then [I, -[q]x]
    du = jnp.stack([fx / zs, zero, -fx * q[:, 0] / zs**2], -1)
    dv = jnp.stack([zero, fy / zs, -fy * q[:, 1] / zs**2], -1)

    def twist(g):  # [n, 3] d r / d q -> [n, 6]
        return jnp.concatenate([g, jnp.cross(q, g)], -1)

    j_i = twist(s[:, 1:2] * du + s[:, 2:3] * dv)
    ez = jnp.stack([zero, zero, jnp.ones_like(z)], -1)
    j_d = twist(s[:, 4:5] * du + s[:, 5:6] * dv + ez / zs[:, None] ** 2)
    r = jnp.stack([s[:, 0] - src, s[:, 3] - 1.0 / zs], -1)
    ok_d = inside & (s[:, 6] > 0.999) & use_depth
    mask = jnp.stack([inside, ok_d], -1) * w[:, None]
    return r, jnp.stack([j_i, j_d], 1), mask


@partial(jax.jit, static_argnames=("iterations",))
def _solve(t, p, src, w, planes, k, robust, damping, use_depth, *, iterations: int):
    """Levenberg-Marquardt over one level: the final ``t``, the Hessian ``[6, 6]`` (in
    units of the robust scales) and the share of points inside the new frame."""
    hp = jax.lax.Precision.HIGHEST
    inverse = jnp.where((w > 0) & (p[:, 2] > 0), 1.0 / jnp.where(p[:, 2] > 0, p[:, 2], 1.0),
                        jnp.nan)
    floor_d = FLOOR_D * jnp.nan_to_num(jnp.nanmedian(inverse), nan=1.0)

    def scales(r, m):
        return jnp.stack([_mad(r[:, 0], m[:, 0], FLOOR_I), _mad(r[:, 1], m[:, 1], floor_d)])

    def normal(r, jac, m):
        sig = scales(r, m)
        rho, wt = _cauchy((r / sig) ** 2, robust)
        ww = (m * wt) / sig**2  # [n, 2]
        jw = jac * ww[..., None]
        h = jnp.einsum("nca,ncb->ab", jw, jac, precision=hp)
        g = jnp.einsum("nca,nc->a", jw, r, precision=hp)
        return jnp.sum(m * rho), g, h, sig

    def step(_, carry):  # the terms at a step's end serve the next step's normal equations
        t, lam, terms = carry
        c0, g, h, sig = normal(*terms)
        a = h + lam * jnp.diag(jnp.diag(h) + 1e-12)
        delta = -jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(a), g)
        new = jnp.matmul(se3_exp(delta), t, precision=hp)
        moved = _terms(new, p, src, w, planes, k, use_depth)
        r, _, m = moved
        keep = jnp.isfinite(delta).all() & (jnp.sum(m * _cauchy((r / sig) ** 2, robust)[0]) < c0)
        pick = lambda a, b: jnp.where(keep, a, b)  # noqa: E731
        return (pick(new, t), pick(lam * DAMP_DOWN, lam * DAMP_UP),
                jax.tree_util.tree_map(pick, moved, terms))

    # unrolled (the step count is static): XLA's CPU loop ran a 128 px frame's full-size
    # level at 2.0 ms a step, the unrolled steps at 1.2 ms (the same results to the bit)
    carry = (t, damping, _terms(t, p, src, w, planes, k, use_depth))
    for i in range(iterations):
        carry = step(i, carry)
    t, _, terms = carry
    _, _, h, sig = normal(*terms)
    m = terms[2]
    return t, h, jnp.sum(m[:, 0]) / jnp.maximum(jnp.sum(w), 1.0), sig[0]


class Level(NamedTuple):
    """One frame at one level of the pyramid, in both roles a frame plays: as the
    previous frame, its pixels with depth (``points [m, 3]`` in its camera's frame,
    ``intensity [m]``, ``weight [m]``: 1, or 0 on padding rows, :func:`_padded`); as the
    new frame, its ``planes [h, w, 7]`` (intensity, its gradient, inverse depth, its
    gradient, where a depth gradient counts) and the level's intrinsics ``k [4]``."""

    points: np.ndarray
    intensity: np.ndarray
    weight: np.ndarray
    planes: np.ndarray
    k: np.ndarray


class Pyramid(NamedTuple):
    """A frame's :class:`Level` at each of ``factors``, built once (:func:`pyramid`):
    a stream's frame is the new frame of one alignment and the previous of the next."""

    factors: tuple[int, ...]
    levels: tuple[Level, ...]
    has_depth: bool  # any pixel with a reading


def pyramid(camera: Camera, rgb, depth, factors=FACTORS, *, names=("rgb", "depth")
            ) -> Pyramid:
    """The :class:`Pyramid` of frame ``rgb [h, w, 3]``, ``depth [h, w]`` (0 or NaN where
    missing) seen by ``camera`` (intrinsics only); ``names``: the arrays' in errors."""
    for name, a, tail in ((names[0], rgb, (3,)), (names[1], depth, ())):
        if np.shape(a) != (camera.height, camera.width) + tail:
            raise ValueError(f"{name} must be {(camera.height, camera.width) + tail} for the "
                             f"camera, got {np.shape(a)}")
    ok = valid_depth(depth)
    depth, intensity = np.where(ok, depth, 0.0), grey(rgb)
    levels = tuple(_level(camera, intensity, depth, int(f)) for f in factors)
    return Pyramid(tuple(int(f) for f in factors), levels, bool(ok.any()))


def _level(camera: Camera, intensity, depth, factor: int) -> Level:
    cam = level_camera(camera, factor)
    d, _ = pool_depth(depth, None, factor)
    ok = valid_depth(d)
    i = pool(intensity, factor)
    gi = _gradient(i)
    dz = np.where(ok, 1.0 / np.where(ok, d, 1.0), 0.0)  # inverse depth
    gd = _gradient(dz)
    # a depth gradient counts only where the pixel and its 4 neighbours have readings
    pad = np.pad(ok, 1)
    full = ok & pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:]
    f32 = np.float32
    planes = np.stack([i, *gi, dz, *gd, full.astype(np.float64)], -1).astype(f32)
    keep = np.flatnonzero(ok.ravel())  # only pixels with depth: the rest would weigh 0
    rows = np.zeros(_padded(len(keep), ok.size), np.int64)
    rows[: len(keep)] = keep
    p = camera_rays(cam).reshape(-1, 3)[rows] * d.ravel()[rows, None]
    w = (np.arange(len(rows)) < len(keep)).astype(f32)
    k = np.array([cam.fx, cam.fy, cam.cx, cam.cy], f32)
    return Level(p.astype(f32), i.ravel()[rows].astype(f32), w, planes, k)


def _padded(n: int, most: int) -> int:
    """Rows a level solves over for ``n`` pixels with depth of ``most``: half the
    level's pixels where they fit (the object's frames, a third of the pixels with
    depth), else all of them; two shapes a level at most, so a stream compiles its
    solver once or twice a level whatever its frames' depth coverage."""
    return most // 2 if n <= most // 2 else most


def align(camera: Camera, rgb_prev, depth_prev, rgb_new, depth_new, guess=None,
          config: DirectConfig = DirectConfig()) -> Motion:
    """The motion ``[4, 4]`` (the new camera's pose in the previous camera's frame) from
    frame ``(rgb_prev, depth_prev)`` to ``(rgb_new, depth_new)`` (``[h, w, 3]``, ``[h,
    w]``; depth 0 or NaN where missing) seen by ``camera`` (intrinsics only), starting
    from the motion ``guess`` (None: no motion)."""
    prev, new = _pyramids(camera, rgb_prev, depth_prev, rgb_new, depth_new, config)
    return align_pyramids(prev, new, guess, config)


def _pyramids(camera, rgb_prev, depth_prev, rgb_new, depth_new, config: DirectConfig
              ) -> tuple[Pyramid, Pyramid]:
    """The previous and the new frame's :class:`Pyramid` (errors name the arrays as
    :func:`align` and :func:`search` take them)."""
    return tuple(pyramid(camera, rgb, depth, config.factors,
                         names=(f"rgb_{when}", f"depth_{when}"))
                 for rgb, depth, when in ((rgb_prev, depth_prev, "prev"),
                                          (rgb_new, depth_new, "new")))


def align_pyramids(prev: Pyramid, new: Pyramid, guess=None,
                   config: DirectConfig = DirectConfig()) -> Motion:
    """:func:`align` between two frames' :class:`Pyramid`, built with the ``factors``
    of ``config``."""
    factors = tuple(int(f) for f in config.factors)
    if prev.factors != factors or new.factors != factors:
        raise ValueError(f"the pyramids' levels {prev.factors} and {new.factors} are not "
                         f"the config's {factors}")
    if not prev.has_depth:
        raise ValueError("the previous frame has no pixel with depth: no motion to align")
    motion = np.eye(4) if guess is None else orthonormalise(np.asarray(guess, np.float64))
    t = inverse(motion)
    h, matched, residual = np.zeros((6, 6)), 0.0, np.inf
    for a, b, iterations in zip(prev.levels, new.levels, config.iterations, strict=True):
        if a.weight.sum() < 6:  # too coarse for this frame's depth: the next level
            continue
        out, h, matched, residual = _solve(jnp.asarray(t, jnp.float32), a.points, a.intensity,
                                           a.weight, b.planes, b.k, float(config.robust),
                                           float(config.damping), bool(config.depth),
                                           iterations=int(iterations))
        t = orthonormalise(np.asarray(out, np.float64))
    return Motion(inverse(t), np.asarray(h, np.float64), float(matched), float(residual))


# A start of :func:`search` counts only where this share of the previous frame's depth
# pixels stays in the new frame (a motion that pushes the points out of view leaves a
# few well-matched ones: a low residual that says nothing).
MIN_MATCHED = 0.2


def search(camera: Camera, rgb_prev, depth_prev, rgb_new, depth_new, starts,
           config: DirectConfig = DirectConfig()) -> Motion:
    """:func:`align` from each of the motions ``starts [m, 4, 4]``; the result whose
    final intensity residual (``Motion.residual``) is lowest among those that keep
    :data:`MIN_MATCHED` of the points in view (the first start's when none does). For
    a frame with no motion guess (the second of a track)."""
    prev, new = _pyramids(camera, rgb_prev, depth_prev, rgb_new, depth_new, config)
    return search_pyramids(prev, new, starts, config)


def search_pyramids(prev: Pyramid, new: Pyramid, starts,
                    config: DirectConfig = DirectConfig()) -> Motion:
    """:func:`search` between two frames' :class:`Pyramid`."""
    found = [align_pyramids(prev, new, s, config) for s in np.asarray(starts, np.float64)]
    score = [m.residual if m.matched >= MIN_MATCHED else np.inf for m in found]
    return found[int(np.argmin(score))] if np.isfinite(min(score)) else found[0]
