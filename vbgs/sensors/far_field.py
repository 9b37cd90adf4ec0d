"""A depth network's far field: the sky and empty background it gives depth to.

A depth network predicts depth on every pixel, sky and empty background included
(:mod:`vbgs.sensors.mono` puts them at 1.5 times the frame's largest depth; a disparity
network near zero disparity). Taken as surface they become a shell of splats around
the scene. :func:`far_field` finds them from the frame's depth alone, as the pixels
beyond the farthest gap in its depths that form a plateau there; made depth-less, they
are then background by :func:`vbgs.render.background.empty_pixels` (depth-less and
reaching the image border), as empty space seen by a depth sensor is.

With ``l_(1) <= ... <= l_(n)`` the sorted log depths of the frame's pixels off its depth
edges (a 3x3 neighbourhood spanning less than ``log(gap) / 2``: depth bled across an
edge fills a gap with a ramp), the farthest gap is the largest ``i`` with

    l_(i + k) - l_(i) > log(gap),

``k - 1`` the strays allowed inside it (``FAR_GAP_STRAYS`` of ``n``, at least
``FAR_GAP_STRAYS_MIN``). The far field is every pixel deeper than ``exp(l_(i))``, edge
pixels included, provided the pixels off the edges beyond it form a plateau: their
2nd to 98th percentile span at most ``plateau``. A network saturates on the sky (its
disparity there is flat near zero), so its aligned depth there is flat; the far part
of a room behind a near stool spans walls at many depths and is kept. No gap (a room,
a street running to the horizon) or no plateau beyond it: no far field. A flat surface
behind such a gap with nothing in between (a plain wall far behind an object, seen
through no floor) would be taken for far field too: depth alone cannot tell them apart.
"""

from __future__ import annotations

import numpy as np

from vbgs.sensors.holes import valid

# The gap: no pixel (but a few strays) has depth between z and FAR_GAP * z. The mono
# model's fill sits at 1.5 times the frame's largest depth, at least 1.36 times after
# its +-5 % warp; a room at 64 px has gaps of 1.2-1.33 behind near objects (kept by
# the plateau test).
FAR_GAP = 1.2
# Strays allowed inside the gap, as a share of the frame's pixels with depth.
FAR_GAP_STRAYS = 0.002
FAR_GAP_STRAYS_MIN = 3
# The plateau beyond the gap spans at most this depth ratio (2nd to 98th percentile);
# the mono model's fill spans its warp, at most 1.05 / 0.95 = 1.11.
FAR_PLATEAU = 1.25
FAR_PLATEAU_QUANTILES = (2.0, 98.0)


def edge_band(log_z: np.ndarray, ok: np.ndarray, jump: float) -> np.ndarray:
    """``[h, w]`` bool: pixels with depth whose 3x3 neighbourhood spans more than
    ``jump`` in ``log_z [h, w]`` (a depth edge and the depth bled across it); depth-less
    neighbours (``~ok``) are ignored."""
    from scipy import ndimage  # imported when used

    hi = ndimage.maximum_filter(np.where(ok, log_z, -np.inf), size=3, mode="nearest")
    lo = ndimage.minimum_filter(np.where(ok, log_z, np.inf), size=3, mode="nearest")
    return ok & (hi - lo > jump)


def far_field(depth: np.ndarray, gap: float = FAR_GAP, plateau: float = FAR_PLATEAU
              ) -> np.ndarray:
    """``[h, w]`` bool: the pixels of ``depth [h, w]`` beyond its farthest gap, where they
    form a plateau (module docstring); none if there is no such gap."""
    depth = np.asarray(depth, np.float64)
    ok = valid(depth)
    far = np.zeros(depth.shape, bool)
    if not ok.any():
        return far
    log_z = np.log(np.where(ok, depth, 1.0))
    jump = float(np.log(gap))
    steady = np.sort(log_z[ok & ~edge_band(log_z, ok, jump / 2)])  # [n]
    k = max(FAR_GAP_STRAYS_MIN, int(FAR_GAP_STRAYS * ok.sum()))
    if len(steady) <= k:
        return far
    wide = np.flatnonzero(steady[k:] - steady[:-k] > jump)  # windows across a gap
    if not len(wide):
        return far
    cut = steady[int(wide[-1])]  # the farthest gap's near side (a stray at worst)
    lo, hi = np.percentile(steady[steady > cut], FAR_PLATEAU_QUANTILES)
    if hi - lo > np.log(plateau):
        return far
    return ok & (log_z > cut)
