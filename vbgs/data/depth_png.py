"""16-bit PNG depth maps: the on-disk depth format shared by loaders and writers.

A stored value ``q`` (uint16) means depth ``q / scale`` in scene units; 0 means
"no depth". ``scale`` is 1000 for millimetres (Blender layout written here),
6553.5 for Replica as packaged by SplaTAM, 5000 for TUM RGB-D.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from skimage import io as skio

MILLIMETRES = 1000.0
_MAX_CODE = np.iinfo(np.uint16).max


def read_depth_png(path: str | Path, scale: float = MILLIMETRES) -> np.ndarray:
    """Read a 16-bit depth PNG as float32 depth ``[h, w]``; missing depth becomes 0."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"depth image not found: {path}")
    raw = skio.imread(path)
    if raw.ndim == 3:  # some writers store depth as grey replicated to RGB
        raw = raw[..., 0]
    if raw.ndim != 2 or not np.issubdtype(raw.dtype, np.integer):
        raise ValueError(
            f"{path}: expected a single-channel 16-bit integer depth PNG, got dtype {raw.dtype} "
            f"and shape {raw.shape}"
        )
    return (raw.astype(np.float64) / scale).astype(np.float32)


def write_depth_png(path: str | Path, depth: np.ndarray, scale: float = MILLIMETRES) -> None:
    """Write depth ``[h, w]`` in scene units as a 16-bit PNG of ``depth * scale``.

    Invalid depth (NaN, inf, <= 0) is stored as 0; depth beyond the 16-bit range is
    refused rather than silently wrapped.
    """
    depth = np.asarray(depth, np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth must be a 2-D array [h, w], got shape {depth.shape}")
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0)
    code = np.where(valid, np.round(np.where(valid, depth, 0.0) * scale), 0.0)
    if code.max(initial=0.0) > _MAX_CODE:
        raise ValueError(
            f"depth up to {depth[valid].max():.3f} does not fit a 16-bit PNG at scale {scale} "
            f"(maximum {_MAX_CODE / scale:.3f}); use a smaller scale"
        )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    skio.imsave(path, code.astype(np.uint16), check_contrast=False)
