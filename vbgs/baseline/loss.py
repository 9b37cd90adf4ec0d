"""Photometric (and optional depth) loss of the gradient baseline.

    L = (1 - λ) · mean |Î - I| + λ · (1 - SSIM(Î, I)) + w_depth · L_depth

with λ = SSIM_LAMBDA = 0.2 as in 3DGS, SSIM with the 3DGS papers' 11x11 Gaussian
window (sigma 1.5; the constants of :mod:`vbgs.render.metrics`), and the depth term

    L_depth = Σ_p m_p |D_p / α_p - d_p| / max(1, Σ_p m_p),
    m_p = [d_p valid] · [α_p > SURFACE_ALPHA],

the L1 between the *alpha-normalised* rendered depth (the depth of the visible
surface, as the evaluation renders it) and the ground truth, over pixels with
valid ground-truth depth that the splats cover. Pixels the splats do not cover
yet are left to the photometric term (dividing by a tiny α would blow up).

Measured depth (a sensor's) weights each pixel's term by ``s_ref / sigma_z(d_p)``, the
inverse of its noise relative to the frame's median noise ``s_ref`` (an L1 term is the
log-likelihood of a Laplace error, whose scale grows with sigma_z), so far and noisy
readings pull less; a sensor's holes are invalid pixels and take no part
(:func:`vbgs.mapping.measurement.depth_weights` computes the weights).
"""

from __future__ import annotations

import dm_pix
import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.precision import tensordot
from vbgs.render.metrics import SSIM_SIGMA, ssim_window
from vbgs.render.raster import visible_surface

SSIM_LAMBDA = 0.2  # weight of (1 - SSIM); 3DGS's λ_D-SSIM


def gaussian_band(n: int, window: int, sigma: float = SSIM_SIGMA) -> np.ndarray:
    """``G [n - window + 1, n]``: row i holds the normalised 1-D Gaussian window
    ``g_j ∝ exp(-½ ((j - window // 2) / σ)²)`` at columns ``i .. i + window - 1``, so
    ``G @ z`` is the 'valid' convolution of z with it (the window is symmetric)."""
    half = window // 2
    taps = np.exp(-0.5 * ((np.arange(window) - half) / sigma) ** 2)
    taps /= taps.sum()
    band = np.zeros((n - window + 1, n), np.float32)
    for i in range(n - window + 1):
        band[i, i : i + window] = taps
    return band


def ssim_filter(height: int, width: int, window: int):
    """dm-pix's separable Gaussian SSIM blur (same window, same 'valid' output) as two
    banded matmuls: ``z [h, w, c] -> G_h z G_wᵀ [h', w', c]``. On CPU this is ~15x
    faster than dm-pix's vmapped 1-D convolutions, forward and backward. The products run
    at full float32 precision: SSIM's variances ``E[z²] - E[z]²`` cancel, and TF32-rounded
    blurs would not survive it."""
    g_rows = jnp.asarray(gaussian_band(height, window))  # [h', h]
    g_cols = jnp.asarray(gaussian_band(width, window))  # [w', w]

    def blur(z):
        z = tensordot(g_rows, z, axes=(1, 0))  # [h', w, c]
        return jnp.swapaxes(tensordot(g_cols, z, axes=(1, 1)), 0, 1)  # [h', w', c]

    return blur


def ssim_of(render, target) -> jax.Array:
    """Mean SSIM of ``[h, w, 3]`` images: dm-pix's, with the 3DGS window (11x11 Gaussian,
    σ 1.5; smaller images use :func:`vbgs.render.metrics.ssim_window`) and a faster blur."""
    height, width = target.shape[0], target.shape[1]
    window = ssim_window(height, width)
    return dm_pix.ssim(render, target, max_val=1.0, filter_size=window, filter_sigma=SSIM_SIGMA,
                       filter_fn=ssim_filter(height, width, window))


def image_loss(render, target, ssim_weight: float = SSIM_LAMBDA) -> jax.Array:
    """``(1 - λ) mean|render - target| + λ (1 - SSIM)`` of ``[h, w, 3]`` images."""
    l1 = jnp.mean(jnp.abs(render - target))
    return (1.0 - ssim_weight) * l1 + ssim_weight * (1.0 - ssim_of(render, target))


def depth_loss(depth_sum, alpha, target_depth, pixel_weight=None) -> jax.Array:
    """Masked L1 of the alpha-normalised depth (see the module docstring).

    depth_sum: ``[h, w]`` un-normalised Σ z α T; alpha: ``[h, w]``; target_depth:
    ``[h, w]`` with 0 (or non-finite) where invalid; pixel_weight: ``[h, w]`` or None
    (exact depth: every pixel 1).
    """
    valid = jnp.isfinite(target_depth) & (target_depth > 0)
    surface, covered = visible_surface(depth_sum, alpha)
    mask = valid & covered
    err = jnp.where(mask, jnp.abs(surface - jnp.where(valid, target_depth, 0.0)), 0.0)
    if pixel_weight is not None:
        err = err * pixel_weight
    return jnp.sum(err) / jnp.maximum(1.0, jnp.sum(mask))


def frame_loss(out, rgb, depth, *, ssim_weight: float = SSIM_LAMBDA,
               depth_weight: float = 0.0, pixel_weight=None) -> jax.Array:
    """The full loss of one rendered view ``out`` (a :class:`vbgs.render.raster.RenderOutput`)
    against the frame's ``rgb [h, w, 3]`` and ``depth [h, w]`` (its pixels weighted by
    ``pixel_weight [h, w]`` when the depth was measured)."""
    loss = image_loss(out.rgb, rgb, ssim_weight)
    if depth_weight:
        loss = loss + depth_weight * depth_loss(out.depth, out.alpha, depth, pixel_weight)
    return loss
