"""Frame checks, input-size rules, separable linear resizing and normalisation.

Pure numpy; shared by :class:`depth.OnnxDepth` on the way in (frames -> model input)
and on the way out (prediction -> frame size).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from vbgs.render.pixels import PIXEL_CENTRE_OFFSET, pixel_centre

UINT8_MAX = 255.0
RANGE_TOLERANCE = 1e-3  # float frames may stray this far outside [0, 1] (rounding)
RGB = 3


def as_frames(frames) -> tuple[np.ndarray, bool]:
    """Validate frames and return ``(float32 [n, h, w, 3] in [0, 1], was_single)``.

    Accepts one ``[h, w, 3]`` image or a list/array ``[n, h, w, 3]`` of same-size
    images, as uint8 (divided by 255) or float in [0, 1]. Refuses anything else
    with a message that says what to change.
    """
    if isinstance(frames, np.ndarray):
        if frames.ndim == 3:
            return _check_batch(frames[None], "frame"), True
        if frames.ndim == 4:
            return _check_batch(frames, "frames"), False
        if frames.ndim == 2:
            _check_one(frames, "frame")
        raise ValueError(
            f"frames must be one [h, w, 3] image or a batch [n, h, w, 3], got shape {frames.shape}"
        )
    if isinstance(frames, Sequence) and not isinstance(frames, (str, bytes)):
        if len(frames) == 0:
            raise ValueError("no frames given: pass one [h, w, 3] image or a non-empty list")
        arrays = [np.asarray(f) for f in frames]
        for i, a in enumerate(arrays):
            _check_one(a, f"frame {i}")
        shapes = {a.shape for a in arrays}
        if len(shapes) > 1:
            raise ValueError(
                f"frames in one call must share a size, got {sorted(shapes)}; "
                "call predict separately for each size"
            )
        return _check_batch(np.stack(arrays), "frames"), False
    raise TypeError(
        f"frames must be a numpy array or a list of arrays, got {type(frames).__name__}"
    )


def _check_one(a: np.ndarray, what: str) -> None:
    """Refuse anything that is not one RGB image ``[h, w, 3]``."""
    if a.ndim == 2:
        raise ValueError(
            f"{what} is greyscale {a.shape}; depth models take RGB [h, w, 3]: "
            "use np.repeat(img[..., None], 3, axis=-1)"
        )
    if a.ndim != 3 or a.shape[-1] != RGB:
        hint = " (drop alpha with img[..., :3])" if a.ndim == 3 and a.shape[-1] == 4 else ""
        raise ValueError(f"{what} must be an RGB image [h, w, 3], got shape {a.shape}{hint}")


def _check_batch(batch: np.ndarray, what: str) -> np.ndarray:
    if batch.shape[0] == 0:
        raise ValueError("no frames given: the batch [n, h, w, 3] has n = 0")
    _check_one(batch[0], what)
    if batch.shape[1] == 0 or batch.shape[2] == 0:
        raise ValueError(f"{what} have an empty size {batch.shape[1:3]}")
    if batch.dtype == np.uint8:
        return batch.astype(np.float32) * np.float32(1.0 / UINT8_MAX)
    if not np.issubdtype(batch.dtype, np.floating):
        raise ValueError(
            f"{what} must be uint8 or float in [0, 1], got dtype {batch.dtype}; "
            "convert with img.astype(np.float32) / max_value"
        )
    batch = batch.astype(np.float32, copy=False)
    lo, hi = float(batch.min()), float(batch.max())  # NaN propagates, inf shows: one pass each
    if not (np.isfinite(lo) and np.isfinite(hi)):
        bad = int(np.flatnonzero(~np.isfinite(batch).reshape(len(batch), -1).all(axis=1))[0])
        raise ValueError(f"{what}: frame {bad} contains NaN or inf values; clean the image first")
    if lo < -RANGE_TOLERANCE or hi > 1.0 + RANGE_TOLERANCE:
        raise ValueError(
            f"float {what} must lie in [0, 1], got values in [{lo:g}, {hi:g}]; "
            "divide 0-255 images by 255 or pass them as uint8"
        )
    return batch


def round_to_multiple(x: float, multiple: int) -> int:
    """Nearest multiple of ``multiple`` to ``x``, and at least one multiple."""
    return max(multiple, int(round(x / multiple)) * multiple)


def input_hw(
    frame_hw: tuple[int, int],
    input_size: int | tuple[int, int] | None,
    keep_aspect: bool,
    multiple_of: int,
    fixed_hw: tuple[int | None, int | None] = (None, None),
) -> tuple[int, int]:
    """The model input size ``(H, W)`` for a frame of size ``frame_hw``.

    - sides fixed by the graph (``fixed_hw``) are used as they are;
    - ``input_size=(H, W)``: that size;
    - ``input_size=s`` with ``keep_aspect``: scale ``f = s / min(h, w)``, sides ``(f h, f w)``;
    - ``input_size=s`` without: ``(s, s)``;
    - ``input_size=None``: the frame's size;
    each free side rounded to the nearest multiple of ``multiple_of``.
    """
    h, w = frame_hw
    if input_size is None:
        want = (float(h), float(w))
    elif isinstance(input_size, (tuple, list)):
        want = (float(input_size[0]), float(input_size[1]))
    elif keep_aspect:
        f = input_size / min(h, w)
        want = (f * h, f * w)
    else:
        want = (float(input_size), float(input_size))
    return tuple(
        fixed if fixed is not None else round_to_multiple(side, multiple_of)
        for side, fixed in zip(want, fixed_hw, strict=True)
    )


@lru_cache(maxsize=64)
def _axis_taps(n_in: int, n_out: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices and weights ``[n_out, taps]`` of linear (triangle) resampling on one axis.

    Pixel centres map as ``u_in = (u_out + 0.5) * n_in / n_out - 0.5`` (half-pixel
    convention). The triangle kernel ``max(0, 1 - |u - u_in| / r)`` has radius
    ``r = max(1, n_in / n_out)``: plain bilinear interpolation when enlarging and
    an anti-aliasing area-like filter when shrinking. Edges are replicated and each
    row of weights sums to one.
    """
    ratio = n_in / n_out
    radius = max(1.0, ratio)
    centre = pixel_centre(np.arange(n_out)) * ratio - PIXEL_CENTRE_OFFSET  # [n_out] in input pixels
    taps = int(np.ceil(2 * radius)) + 1
    first = np.floor(centre - radius).astype(np.int64) + 1
    idx = first[:, None] + np.arange(taps)[None, :]
    weight = np.clip(1.0 - np.abs(idx - centre[:, None]) / radius, 0.0, None)
    weight /= weight.sum(axis=1, keepdims=True)
    keep = weight.any(axis=0)  # drop tap columns that are zero everywhere
    return np.clip(idx[:, keep], 0, n_in - 1), weight[:, keep].astype(np.float32)


def _resize_axis(a: np.ndarray, n_out: int, axis: int) -> np.ndarray:
    n_in = a.shape[axis]
    if n_in == n_out:
        return a
    idx, weight = _axis_taps(n_in, n_out)
    shape = [1] * a.ndim
    shape[axis] = n_out
    out = np.zeros(a.shape[:axis] + (n_out,) + a.shape[axis + 1:], np.float32)
    for t in range(idx.shape[1]):
        out += np.take(a, idx[:, t], axis=axis) * weight[:, t].reshape(shape)
    return out


def resize(images: np.ndarray, hw: tuple[int, int], spatial_axes: tuple[int, int]) -> np.ndarray:
    """Resize ``images`` to ``hw`` along ``spatial_axes`` (e.g. ``(1, 2)`` for [n, h, w, c])."""
    out = _resize_axis(np.asarray(images, np.float32), hw[0], spatial_axes[0])
    return _resize_axis(out, hw[1], spatial_axes[1])


def normalise(rgb: np.ndarray, mean: Sequence[float], std: Sequence[float]) -> np.ndarray:
    """``x_c = (rgb_c - mean_c) / std_c`` over the last axis: the plain reference
    formula that :func:`to_model_input` computes faster."""
    return (np.asarray(rgb, np.float32) - np.asarray(mean, np.float32)) / np.asarray(
        std, np.float32
    )


def to_model_input(rgb: np.ndarray, mean: Sequence[float], std: Sequence[float],
                   layout: str, dtype=np.float32) -> np.ndarray:
    """Frames ``[n, h, w, 3]`` -> normalised, contiguous ``[n, 3, h, w]`` (NCHW) or
    ``[n, h, w, 3]`` (NHWC) of ``dtype``; equal to :func:`normalise` then transpose.

    Lays the channels out first and normalises in place, per channel plane in NCHW,
    so no numpy inner loop runs over an axis of length 3.
    """
    mean = np.asarray(mean, np.float32)
    inv_std = (1.0 / np.asarray(std, np.float32)).astype(np.float32)
    if layout == "NCHW":
        x = np.ascontiguousarray(rgb.transpose(0, 3, 1, 2), dtype=np.float32)
        scale = (slice(None), None, None)
    else:
        x = np.array(rgb, dtype=np.float32, order="C")
        scale = (slice(None),)
    if mean.any():
        x -= mean[scale]
    if (inv_std != 1.0).any():
        x *= inv_std[scale]
    return x if x.dtype == dtype else x.astype(dtype)
