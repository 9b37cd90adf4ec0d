"""16-bit PNG depth maps: the on-disk depth format shared by loaders and writers.

A stored value ``q`` (uint16) means depth ``q / scale`` in scene units; 0 means
"no depth". ``scale`` is 1000 for millimetres (Blender layout written here),
6553.5 for Replica as packaged by SplaTAM, 5000 for TUM RGB-D.

Only 16-bit PNGs are read: an 8-bit file (a depth *visualisation*, or depth
saved by a viewer) would read as 0-255 codes, 0-0.255 m at millimetre scale, a
plausible-looking but wrong depth, so it is refused naming the file. Depth
stored as grey replicated to RGB is accepted; RGB whose channels differ is a
colour image, not depth, and is refused too. Writes are atomic
(:mod:`vbgs.io_atomic`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from skimage import io as skio

from vbgs.data.images import read_image_file
from vbgs.io_atomic import write_atomic

MILLIMETRES = 1000.0
_MAX_CODE = np.iinfo(np.uint16).max


def read_depth_png(path: str | Path, scale: float = MILLIMETRES) -> np.ndarray:
    """Read a 16-bit depth PNG as float32 depth ``[h, w]``; missing depth becomes 0."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"depth image not found: {path}")
    raw = read_image_file(path)
    if raw.ndim == 3 and raw.shape[-1] in (3, 4):  # grey replicated to RGB(A) by some writers
        if np.any(raw[..., 1:3] != raw[..., :1]):
            raise ValueError(
                f"{path}: a colour image, not a depth map (its RGB channels differ); depth PNGs "
                f"hold one 16-bit channel of depth * {scale:g}"
            )
        raw = raw[..., 0]
    if raw.ndim != 2 or raw.dtype != np.uint16:
        got = "8-bit" if raw.dtype == np.uint8 else f"{raw.dtype} with shape {raw.shape}"
        raise ValueError(
            f"{path}: depth PNGs must be 16-bit single-channel (value = depth * {scale:g}), "
            f"this one is {got}; re-save the depth as a 16-bit PNG"
        )
    return (raw.astype(np.float64) / scale).astype(np.float32)


def write_depth_png(path: str | Path, depth: np.ndarray, scale: float = MILLIMETRES) -> None:
    """Write depth ``[h, w]`` in scene units as a 16-bit PNG of ``depth * scale``.

    Invalid depth (NaN, inf, <= 0) is stored as 0; depth beyond the 16-bit range is
    refused rather than silently wrapped. The file appears complete or not at all.
    """
    depth = np.asarray(depth, np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth must be a 2-D array [h, w], got shape {depth.shape}")
    valid, code = _codes(depth, scale)
    if code.max(initial=0.0) > _MAX_CODE:
        raise ValueError(
            f"depth up to {depth[valid].max():.3f} does not fit a 16-bit PNG at scale {scale} "
            f"(maximum {_MAX_CODE / scale:.3f}); use a smaller scale"
        )
    code16 = code.astype(np.uint16)
    write_atomic(path, lambda tmp: skio.imsave(tmp, code16, check_contrast=False))


def _codes(depth: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The valid pixels ``[h, w]`` (finite, > 0) and their codes ``round(depth * scale)``
    (0 elsewhere), float64, before any range check."""
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0)
    return valid, np.where(valid, np.round(np.where(valid, depth, 0.0) * scale), 0.0)


def fits_depth_png(depth, scale: float = MILLIMETRES) -> bool:
    """Whether :func:`write_depth_png` can store ``depth`` at ``scale`` (its largest
    code within 16 bits)."""
    return bool(_codes(np.asarray(depth, np.float64), scale)[1].max(initial=0.0) <= _MAX_CODE)
