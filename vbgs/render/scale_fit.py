"""The splat scale chosen on the frames a map has learned (``splat_scale = "auto"``).

A VBGS splat is its component's expected covariance times ``splat_scale^2``
(:mod:`vbgs.render.splats`). The default, 1.2, was chosen on validation views of maps
whose components hold a dozen points or more. Where they hold a few (an open walk at
50k components: a median of 5.8 points), the splats are about a pixel across and leave
gaps, and a larger scale draws better; where they hold many, it blurs. Here the scale
is the one of ``SCALES`` that draws the map's own training frames best (mean PSNR over
frames that have arrived, never a held-out view): one number fitted to the data the
map learned, as its colours and opacities are.

Chosen so (fit-scene's defaults, 128 px / 60 frames, `python -m
experiments.studies.val_probe fit-scene --scene S --components K --splat-scale auto`:
`results/tuning/splat_scale/auto_val_*.json`; the grid's validation scores at each
fixed scale are beside them), the scale is 1.2 on the object, the room and the walk at
20k components and on the object and the room at 50k, and 1.5 on the walk at 50k: on each
the validation best of 1.2, 1.35 and 1.5 (`results/tuning/splat_scale/k20000_*`,
`k50000_*`).
"""

from __future__ import annotations

import numpy as np

from vbgs.render.metrics import psnr
from vbgs.render.splats import Splats
from vbgs.render.views import render_view

# The scales tried (sigma multipliers), the default 1.2 among them.
SCALES = (1.0, 1.1, 1.2, 1.35, 1.5)
# Another scale replaces the base only when it draws the frames better by more than this
# (dB of mean PSNR). The frames are the ones the map learned, which favour sharper
# splats a little; the margin keeps a scale that only draws them better. Chosen on
# validation runs (`results/tuning/splat_scale/auto_val_*.json`; docs/validation.md).
MARGIN_DB = 0.2


def rescaled(splats: Splats, base: float, scale: float) -> Splats:
    """``splats`` drawn at ``scale`` in place of ``base`` (covariances times
    ``(scale / base)^2``)."""
    return splats._replace(covs=splats.covs * np.float32((scale / base) ** 2))


def choose_scale(splats: Splats, frames, background, blur: float, base: float,
                 scales=SCALES, margin: float = MARGIN_DB) -> tuple[float, list[float]]:
    """The scale of ``scales`` at which ``splats`` (made at ``base``) draw ``frames``
    best over ``background`` with pixel filter ``blur``: ``(scale, mean PSNR at each
    scale)``. ``base`` (when among ``scales``) stays unless the best draws them better by
    more than ``margin`` dB; a tie goes to the scale nearest ``base``."""
    if not frames:
        raise ValueError("no frames to choose a splat scale on")
    scores = [float(np.mean([psnr(render_view(rescaled(splats, base, s), f, background,
                                              blur).rgb, f.rgb) for f in frames]))
              for s in scales]
    best = max(range(len(scales)), key=lambda i: (scores[i], -abs(scales[i] - base)))
    if base in scales and scores[best] - scores[scales.index(base)] <= margin:
        return float(base), scores
    return float(scales[best]), scores
