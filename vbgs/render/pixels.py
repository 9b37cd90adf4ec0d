"""Pixel centres: the one definition, NumPy only (cheap to import, for ``depth`` too).

Pixel ``(row, col)`` covers ``[col, col + 1) x [row, row + 1)`` in image coordinates,
so its centre is ``(u, v) = (col + 0.5, row + 0.5)`` (see :mod:`vbgs.render.camera` for the
camera conventions built on it).
"""

from __future__ import annotations

import numpy as np

PIXEL_CENTRE_OFFSET = 0.5


def pixel_centre(index):
    """Image coordinate of the centre of pixel ``index``: ``index + 0.5``.

    The one definition of pixel centres: column ``col`` -> ``u``, row ``row`` -> ``v``.
    Works on ints, NumPy and JAX arrays (the dtype follows ``index``).
    """
    return index + PIXEL_CENTRE_OFFSET


def pixel_centres(height: int, width: int, dtype=np.float32) -> np.ndarray:
    """``(u, v)`` of every pixel centre in row-major order, ``[h * w, 2]``."""
    v, u = pixel_centre(np.mgrid[0:height, 0:width].astype(dtype))  # [h, w] each
    return np.stack([u.ravel(), v.ravel()], -1)


def pixel_rays(height: int, width: int, fx, fy, cx, cy) -> np.ndarray:
    """``[h, w, 3]`` float64: the ray through each pixel centre in the camera frame
    (OpenCV axes) at unit camera depth, ``((u - cx) / fx, (v - cy) / fy, 1)``; a pixel
    with z-depth ``d`` sees the camera-frame point ``d`` times its ray."""
    v, u = pixel_centre(np.mgrid[0:height, 0:width].astype(np.float64))  # [h, w] each
    return np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], -1)
