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
from vbgs.render.camera import valid_depth
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
    # the share of the views' pixels with ground-truth depth (a surface is there) that
    # the splats leave uncovered (alpha < UNCOVERED_ALPHA): ground drawn as background
    uncovered: float = float("nan")
    view_psnr: tuple = ()  # each view's PSNR, in the order of the views given (psnr: their mean)


# A pixel is uncovered when the splats' accumulated opacity stays below this.
UNCOVERED_ALPHA = 0.5


class View(NamedTuple):
    """One rendered view."""

    rgb: np.ndarray  # [h, w, 3] in [0, 1]
    depth: np.ndarray  # [h, w] alpha-normalised depth, 0 where uncovered
    alpha: np.ndarray  # [h, w] accumulated opacity
    dropped: int  # splat-tile overlaps the tiles dropped (0 by the exact capacity)


def render_view(splats: Splats, frame: Frame, background, blur: float = BLUR_VARIANCE
                ) -> View:
    """Render one view over ``background``; ``blur``: the pixel filter (px²) the splats
    are drawn with."""
    out = rasterize(splats, frame.camera, background=background, blur=blur,
                    capacity=exact_capacity(splats, frame.camera, blur=blur))
    return View(np.clip(np.asarray(out.rgb), 0, 1), surface_depth(out),
                np.asarray(out.alpha), int(out.dropped))


def evaluate(splats: Splats, frames: list[Frame], background, blur: float = BLUR_VARIANCE
             ) -> Evaluation:
    """Mean PSNR, SSIM and depth L1 over ``frames``, plus the renders, the share of
    surface pixels left uncovered and each view's PSNR."""
    if not frames:
        raise ValueError("no views to score")
    scores, renders, dropped, surface, uncovered = [], [], 0, 0, 0
    for frame in frames:
        view = render_view(splats, frame, background, blur)
        dropped += view.dropped
        scores.append((psnr(view.rgb, frame.rgb), ssim(view.rgb, frame.rgb),
                       depth_l1(view.depth, frame.depth)))
        renders.append(view.rgb)
        there = valid_depth(np.asarray(frame.depth))
        surface += int(there.sum())
        uncovered += int((there & (view.alpha < UNCOVERED_ALPHA)).sum())
    psnrs, ssims, l1s = np.asarray(scores).T
    return Evaluation(float(psnrs.mean()), float(ssims.mean()),
                      float(np.nanmean(l1s)) if np.isfinite(l1s).any() else float("nan"),
                      dropped, renders, uncovered / surface if surface else float("nan"),
                      tuple(float(p) for p in psnrs))
