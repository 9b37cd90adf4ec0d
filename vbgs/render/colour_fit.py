"""Splat colours fitted to the picture: least squares over the frames' blending weights.

With the geometry and opacities of the splats fixed, a render is linear in their
colours ``c [k, 3]``. At pixel p of frame f (:mod:`vbgs.render.raster`)

    C_f(p) = Σ_i w_fpi c_i + T_f(p) bg,     w_fpi = α_i T_i,

so the colours that best reproduce the training pixels solve a linear least-squares
problem, with a ridge toward the posterior colour means ``c_post``:

    min_c  Σ_f ||W_f c + T_f bg - C_f||² + RIDGE ||c - c_post||²
    <=>    (A + RIDGE I) c = b + RIDGE c_post,
           A = Σ_f W_fᵀ W_f  [k, k],   b = Σ_f W_fᵀ (C_f - T_f bg)  [k, 3].

A and b add up frame by frame: the stream keeps only them, never the frames.
``W_fᵀ y`` is the vector-Jacobian product of the renderer with respect to the colours
(the render is linear in them), so no second rasterizer is needed.

A is k x k. It is kept **lumped**: replaced by the diagonal of its row sums,

    A_ii ≈ Σ_j A_ij = Σ_p w_pi Σ_j w_pj = Σ_p w_pi α_p = (W_fᵀ α_f)_i summed over f,

one more vjp per frame (α_f the frame's rendered alpha). The lumped system is exact
where the colours of the components that share i's pixels are uniform (then
``Σ_j A_ij c_j = c_i Σ_j A_ij``); elsewhere it gives each component the coverage-weighted
mean of ``(C - T bg) / α`` over its pixels. :func:`exact_colours` solves the full
system by conjugate gradients over stored frames, as a diagnostic of that
approximation only (it needs every frame; the stream cannot use it).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from vbgs.render.camera import Camera
from vbgs.render.raster import BLUR_VARIANCE, exact_capacity, rasterize
from vbgs.render.splats import Splats

# Ridge weight toward the posterior colour, in pixels: the posterior colour (the mean
# colour of the points the component explains) counts as much as RIDGE pixels fully
# covered by the component (A_ii = 1). A component that covers far more than that over
# the frames is set by the picture; one covering less (hidden, faint, or seen in few
# frames) keeps about its posterior colour, so pixels that a few frames' blending
# assigns to it by chance do not make it noisy. 64 was chosen on VALIDATION views
# (never test views; rule: the best mean validation PSNR over the object and the room) by
# `python -m experiments.run tune --scene object room --components 20000 --frames 60
# --size 128 --grid colour_rule=fit,posterior colour_ridge=16,32,64,128,256
# --out results/tuning/colour` (results/tuning/colour/mean.md, its code version in its
# first line): best at 64 under the fit.
RIDGE = 64.0


class ColourNormal(NamedTuple):
    """The lumped normal equations, summed over the frames seen."""

    rhs: jax.Array  # [k, 3] b = Σ_f W_fᵀ (C_f - T_f bg)
    lumped: jax.Array  # [k] Σ_f W_fᵀ α_f, the row sums of A = Σ_f W_fᵀ W_f


def no_frames(k: int) -> ColourNormal:
    """Before any frame: zero sums for ``k`` components."""
    return ColourNormal(jnp.zeros((k, 3), jnp.float32), jnp.zeros(k, jnp.float32))


def observe(normal: ColourNormal, splats: Splats, camera: Camera, rgb, background, *,
            blur: float = BLUR_VARIANCE) -> ColourNormal:
    """Add one frame: its pixels ``rgb [h, w, 3]`` seen by ``camera``, composited over
    ``background`` ([3] or a grey scalar), against ``splats`` (their colours unused)
    rendered with the pixel filter ``blur`` (px², as the splats will be shown)."""
    rhs, lumped = frame_terms(splats, camera, rgb, background, blur=blur)
    return ColourNormal(normal.rhs + rhs, normal.lumped + lumped)


def frame_terms(splats: Splats, camera: Camera, rgb, background, *,
                blur: float = BLUR_VARIANCE) -> tuple[jax.Array, jax.Array]:
    """One frame's ``W_fᵀ (C_f - T_f bg)`` ``[k, 3]`` and ``W_fᵀ α_f`` ``[k]``."""
    target = jnp.asarray(rgb, jnp.float32)
    if target.shape != (camera.height, camera.width, 3):
        raise ValueError(f"frame rgb has shape {target.shape}; the camera sees "
                         f"[{camera.height}, {camera.width}, 3]")
    bg = jnp.broadcast_to(jnp.asarray(background, jnp.float32), (3,))
    return _frame_terms(splats, *_camera_args(camera), target, bg,
                        **_static(splats, camera, blur))


def solve(normal: ColourNormal, posterior_colours, ridge: float = RIDGE) -> jax.Array:
    """Colours ``[k, 3]`` of the lumped system ``(diag(A 1) + ridge) c = b + ridge c_post``,
    clipped to [0, 1]; ``posterior_colours [k, 3]`` is ``c_post``."""
    if ridge <= 0:
        raise ValueError(f"ridge must be > 0 (it keeps unseen components defined), got {ridge}")
    c_post = jnp.asarray(posterior_colours, jnp.float32)
    colours = (normal.rhs + ridge * c_post) / (normal.lumped + ridge)[:, None]
    return jnp.clip(colours, 0.0, 1.0)


def normal_matvec(splats: Splats, camera: Camera, colours, *,
                  blur: float = BLUR_VARIANCE) -> jax.Array:
    """``W_fᵀ W_f x`` ``[k, 3]`` for one frame and ``x = colours [k, 3]``."""
    x = jnp.asarray(colours, jnp.float32)
    return _matvec(splats, *_camera_args(camera), x, **_static(splats, camera, blur))


def exact_colours(splats: Splats, frames, background, posterior_colours, *,
                  ridge: float = RIDGE, iterations: int = 50, tol: float = 1e-4,
                  blur: float = BLUR_VARIANCE):
    """Diagnostic: the full least-squares colours ``[k, 3]`` over ``frames`` (each with
    ``.rgb`` and ``.camera``), all rendered with ``splats``' geometry, by conjugate
    gradients on ``(A + ridge I) c = b + ridge c_post`` preconditioned with the lumped
    diagonal; stops when every column's residual norm is below ``tol`` times its
    right-hand side's, or after ``iterations``. Not clipped. Returns the colours and
    the number of iterations run."""
    frames = list(frames)
    c_post = jnp.asarray(posterior_colours, jnp.float32)
    normal = no_frames(splats.count)
    for frame in frames:
        normal = observe(normal, splats, frame.camera, frame.rgb, background, blur=blur)

    def matvec(x):  # [k, 3] -> (A + ridge I) x
        out = ridge * x
        for frame in frames:
            out = out + normal_matvec(splats, frame.camera, x, blur=blur)
        return out

    precond = 1.0 / (normal.lumped + ridge)[:, None]  # [k, 1]
    rhs = normal.rhs + ridge * c_post
    x = solve(normal, c_post, ridge)  # lumped start
    r = rhs - matvec(x)
    z = precond * r
    p = z
    rz = jnp.sum(r * z, axis=0)  # [3]
    stop = tol * jnp.linalg.norm(rhs, axis=0)
    for it in range(1, iterations + 1):
        ap = matvec(p)
        step = rz / jnp.maximum(jnp.sum(p * ap, axis=0), 1e-30)
        x = x + step * p
        r = r - step * ap
        if bool(jnp.all(jnp.linalg.norm(r, axis=0) <= stop)):
            return x, it
        z = precond * r
        rz_new = jnp.sum(r * z, axis=0)
        p = z + (rz_new / jnp.maximum(rz, 1e-30)) * p
        rz = rz_new
    return x, iterations


def _camera_args(camera: Camera):
    return tuple(jnp.asarray(v, jnp.float32) for v in
                 (camera.fx, camera.fy, camera.cx, camera.cy, camera.pose))


def _static(splats: Splats, camera: Camera, blur: float) -> dict:
    """Image size, pixel filter and a tile capacity that drops no splat (so W_f is the
    exact render)."""
    return {"width": int(camera.width), "height": int(camera.height), "blur": float(blur),
            "capacity": exact_capacity(splats, camera, blur=blur)}


def _render_linear(splats, fx, fy, cx, cy, pose, width, height, capacity, blur):
    """``colours -> (W_f colours [h, w, 3], alpha [h, w])``: the render over a black
    background, linear in the colours."""
    camera = Camera(fx, fy, cx, cy, width, height, pose)

    def render(colours):
        out = rasterize(splats._replace(colours=colours), camera, background=0.0,
                        capacity=capacity, blur=blur)
        return out.rgb, out.alpha

    return render


@functools.partial(jax.jit, static_argnames=("width", "height", "capacity", "blur"))
def _frame_terms(splats, fx, fy, cx, cy, pose, target, background, *, width, height, capacity,
                 blur):
    render = _render_linear(splats, fx, fy, cx, cy, pose, width, height, capacity, blur)
    _, pullback, alpha = jax.vjp(render, splats.colours, has_aux=True)  # alpha [h, w]
    residual = target - (1.0 - alpha)[..., None] * background  # [h, w, 3] C_f - T_f bg
    cotangents = jnp.stack([residual, jnp.broadcast_to(alpha[..., None], target.shape)])
    # One batched pullback for both (the forward pass is recomputed once, not twice:
    # measured about 2x faster than two pullbacks on CPU).
    (both,) = jax.vmap(pullback)(cotangents)  # [2, k, 3]; the alpha columns are equal
    return both[0], both[1, :, 0]


@functools.partial(jax.jit, static_argnames=("width", "height", "capacity", "blur"))
def _matvec(splats, fx, fy, cx, cy, pose, x, *, width, height, capacity, blur):
    render = _render_linear(splats, fx, fy, cx, cy, pose, width, height, capacity, blur)
    wx, pullback, _ = jax.vjp(render, x, has_aux=True)  # W_f x [h, w, 3] (linear in x)
    (out,) = pullback(wx)
    return out


__all__ = ["RIDGE", "ColourNormal", "exact_colours", "frame_terms", "no_frames",
           "normal_matvec", "observe", "solve"]
