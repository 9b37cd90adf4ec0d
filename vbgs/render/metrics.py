"""Image quality: PSNR, SSIM (as in the 3DGS papers) and masked depth L1."""

from __future__ import annotations

import functools

import dm_pix
import jax
import jax.numpy as jnp
import numpy as np

SSIM_WINDOW = 11  # Gaussian window size of the 3DGS papers' SSIM
SSIM_SIGMA = 1.5


def _pair(a, b):
    a, b = jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32)
    if a.shape != b.shape:
        raise ValueError(f"images differ in shape: {a.shape} vs {b.shape}")
    return a, b


@jax.jit
def _mse(a, b):
    return jnp.mean((a - b) ** 2)


def psnr(a, b, data_range: float = 1.0) -> float:
    """``10 log10(data_range^2 / MSE)`` in dB; identical images give ``inf``."""
    a, b = _pair(a, b)
    return psnr_of_mse(float(_mse(a, b)), data_range)  # compiled: one executable


def psnr_of_mse(mse: float, data_range: float = 1.0) -> float:
    """``10 log10(data_range^2 / mse)`` in dB for a mean squared error; 0 gives ``inf``."""
    return float("inf") if mse == 0 else float(10 * np.log10(data_range**2 / mse))


def ssim_window(height: int, width: int) -> int:
    """The SSIM window: 11, or the largest odd size that fits a smaller image."""
    side = min(SSIM_WINDOW, height, width)
    return side if side % 2 else side - 1


def ssim(a, b, data_range: float = 1.0) -> float:
    """Mean SSIM of ``[h, w, c]`` images with an 11x11 Gaussian window (sigma 1.5),
    k1 = 0.01, k2 = 0.03 (dm-pix); images under 11 px use the largest window that fits."""
    a, b = _pair(a, b)
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    return float(_ssim(a, b, data_range, ssim_window(a.shape[0], a.shape[1])))


@functools.partial(jax.jit, static_argnames=("window",))
def _ssim(a, b, data_range, window: int):
    """dm-pix's SSIM compiled as one function (eager, its ~40 operations would each be
    traced and compiled, or loaded from the cache, in every new process)."""
    return dm_pix.ssim(a, b, max_val=data_range, filter_size=window, filter_sigma=SSIM_SIGMA)


def depth_l1(pred, target) -> float:
    """Mean ``|pred - target|`` over pixels whose target depth is valid (finite, > 0)."""
    pred, target = np.asarray(pred, np.float64), np.asarray(target, np.float64)
    if pred.shape != target.shape:
        raise ValueError(f"depth maps differ in shape: {pred.shape} vs {target.shape}")
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(target) & (target > 0)
    if not valid.any():
        return float("nan")
    return float(np.mean(np.abs(pred[valid] - target[valid])))
