"""Splats rendered at held-out views and scored: the one definition of a view's scores.

A view is rendered with the learner's pixel filter ``blur`` over the scene's background
colour, with a tile capacity that drops no splat (:func:`vbgs.render.raster.exact_capacity`);
its rendered depth is the alpha-normalised expected depth
(:func:`vbgs.render.raster.surface_depth`). Scores are PSNR and SSIM against the view's
RGB and depth L1 over the pixels with valid ground-truth depth
(:mod:`vbgs.render.metrics`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.data.scene import Frame
from vbgs.render.metrics import depth_l1, psnr, ssim
from vbgs.render.raster import BLUR_VARIANCE, exact_capacity, rasterize, surface_depth
from vbgs.render.splats import Splats


class Evaluation(NamedTuple):
    """Mean scores over a set of views, and the renders ``[h, w, 3]`` per view."""

    psnr: float
    ssim: float
    depth_l1: float  # nan where no view has ground-truth depth
    dropped: int  # splats the rasterizer's tiles dropped, summed over views
    renders: list


def render_view(splats: Splats, frame: Frame, background, blur: float = BLUR_VARIANCE
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """Render one view: rgb ``[h, w, 3]``, alpha-normalised depth ``[h, w]`` (0 where
    uncovered) and the number of splats the tiles dropped (0 by the exact capacity);
    ``blur``: the pixel filter (px²) the splats are drawn with."""
    out = rasterize(splats, frame.camera, background=background, blur=blur,
                    capacity=exact_capacity(splats, frame.camera, blur=blur))
    return np.clip(np.asarray(out.rgb), 0, 1), surface_depth(out), int(out.dropped)


def evaluate(splats: Splats, frames: list[Frame], background, blur: float = BLUR_VARIANCE
             ) -> Evaluation:
    """Mean PSNR, SSIM and depth L1 over ``frames``, plus the renders."""
    if not frames:
        raise ValueError("no views to score")
    scores, renders, dropped = [], [], 0
    for frame in frames:
        rgb, depth, n = render_view(splats, frame, background, blur)
        dropped += n
        scores.append((psnr(rgb, frame.rgb), ssim(rgb, frame.rgb), depth_l1(depth, frame.depth)))
        renders.append(rgb)
    psnrs, ssims, l1s = np.asarray(scores).T
    return Evaluation(float(psnrs.mean()), float(ssims.mean()),
                      float(np.nanmean(l1s)) if np.isfinite(l1s).any() else float("nan"),
                      dropped, renders)
