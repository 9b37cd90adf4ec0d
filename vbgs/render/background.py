"""The background colour, learned from the data as frames arrive.

Pixels without valid depth (sky, beyond the sensor's range, empty space behind an
object) are not surface: no splat should explain them, and whatever the splats leave
uncovered shows the background there. Its colour is estimated from exactly those
pixels of the frames that have arrived so far, as a running mean:

    b = Σ_frames Σ_{pixels without depth} c  /  #(pixels without depth).

A stream where every pixel has depth (a closed room) has nothing to estimate from;
there the background can only show through holes between splats, and the colour
that minimises the expected squared error of a hole is the mean colour of all the
pixels seen so far, which is then used instead. Both sums are additive over frames,
so the estimate after a stream does not depend on the frames' order and never reads
a frame that has not arrived.

A real sensor also returns no depth where a surface is: at depth edges, grazing
angles, on dark or shiny materials, at random. Such holes are not background. With
``holes=True`` only the pixels of :func:`empty_pixels` count: the depth-less region
connected to the image border (background and sky reach the border; a hole inside a
surface does not), eroded by :data:`EDGE_HOLES_PX` so the holes that line a
silhouette stay out.

The opacity evidence (:mod:`vbgs.render.opacity`) reads the same pixels as passes, and
there the eroded band costs: a splat that reaches past a silhouette is never shown the
background it covers, so silhouettes grow a fringe. Given the frame's colours and the
background estimate, a pixel of that band whose colour is the background's (within
:data:`BACKGROUND_TOL` in every channel) shows the background again; a surface hole
there rarely has the background's colour, and where it does, a splat missing there
costs nothing. No results table holds the validation figures behind this rule:
docs/validation.md ("vbgs.render.background") keeps them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.render.camera import valid_depth

# Fewer depth-less pixels than this fraction of all pixels seen are treated as
# noise (a few dropped depth readings), not as a view of the background.
MIN_EMPTY_FRACTION = 1e-3
# Width (px) of the band of edge holes a depth sensor leaves along a silhouette: taken
# off the border-connected depth-less region (a Kinect drops 1-2 px at depth edges).
EDGE_HOLES_PX = 2
# A depth-less pixel of that band whose colour differs from the background estimate by
# at most this in every channel shows the background (empty_pixels with rgb).
BACKGROUND_TOL = 0.1


class BackgroundEstimate(NamedTuple):
    """Running sums over the frames seen so far (float64; start from :func:`empty`)."""

    empty_sum: np.ndarray  # [3] colour sum over pixels without valid depth
    empty_count: int
    all_sum: np.ndarray  # [3] colour sum over every pixel
    all_count: int


def empty() -> BackgroundEstimate:
    """The estimate before any frame has arrived."""
    return BackgroundEstimate(np.zeros(3), 0, np.zeros(3), 0)


def empty_pixels(depth: np.ndarray, holes: bool = False, max_depth: float = np.inf,
                 rgb: np.ndarray | None = None, background: np.ndarray | None = None,
                 tol: float = BACKGROUND_TOL) -> np.ndarray:
    """``[h, w]`` bool: the pixels that show nothing (background, sky). Exact depth
    (``holes=False``): every pixel without depth. A sensor with holes: the depth-less
    region connected to the image border, less a band of :data:`EDGE_HOLES_PX` along
    the surfaces it meets; with the frame's ``rgb [h, w, 3]`` and a ``background [3]``
    the band's pixels of the background's colour (within ``tol``) are empty again
    (module docstring). The regions are read off one labelling of the connected
    depth-less pixels each (:func:`_touching`), the same pixels as SciPy's binary
    propagation gives, in a third of its time (8 ms against 29 at 640 x 480)."""
    no_depth = ~valid_depth(depth, max_depth)
    if not holes:
        return no_depth
    from scipy import ndimage  # imported when used

    inner = _eroded(no_depth, EDGE_HOLES_PX)
    labels, _ = ndimage.label(inner)  # 4-connected, as the erosion's cross
    empty = _touching(labels, np.concatenate(
        [labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    if rgb is None or background is None or not empty.any():
        return empty
    # the band: depth-less pixels joined to the empty region through depth-less pixels
    labels, _ = ndimage.label(no_depth)
    band = np.flatnonzero(_touching(labels, labels[empty]) & ~empty)
    like = np.all(np.abs(np.asarray(rgb, np.float32).reshape(-1, 3)[band]
                         - np.asarray(background, np.float32)) <= tol, axis=-1)
    empty.flat[band[like]] = True  # the band's pixels of the background's colour
    return empty


def _eroded(mask: np.ndarray, steps: int) -> np.ndarray:
    """``mask [h, w]`` (bool) eroded ``steps`` times by the 4-neighbour cross, the
    outside of the image counting as set: a pixel stays where every pixel within
    ``steps`` of it (city-block distance) is set. Slices of one padded copy a step, as
    ``scipy.ndimage.binary_erosion(mask, iterations=steps, border_value=1)`` gives it
    (a tenth of its time at 640 x 480)."""
    out = mask
    for _ in range(steps):
        p = np.pad(out, 1, constant_values=True)
        out = p[1:-1, 1:-1] & p[:-2, 1:-1] & p[2:, 1:-1] & p[1:-1, :-2] & p[1:-1, 2:]
    return out


def _touching(labels: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """``[h, w]`` bool: the pixels of ``labels [h, w]``'s components (``ndimage.label``,
    0 the background) that hold a pixel of label ``seeds [m]``: the components a
    propagation from those pixels within the labelled mask fills
    (``ndimage.binary_propagation``), read off one labelling (a union-find pass)
    rather than dilated to convergence."""
    keep = np.zeros(int(labels.max()) + 1, bool)
    keep[seeds] = True
    keep[0] = False
    return keep[labels]


def observe(estimate: BackgroundEstimate, rgb: np.ndarray, depth: np.ndarray,
            max_depth: float = np.inf, holes: bool = False) -> BackgroundEstimate:
    """Add one frame: ``rgb [h, w, 3]`` in [0, 1] and ``depth [h, w]`` (0/NaN/inf or
    beyond ``max_depth`` mark pixels without depth); ``holes``: the depth may miss
    surfaces (a sensor's), so only :func:`empty_pixels` count as background."""
    rgb = np.asarray(rgb, np.float64).reshape(-1, 3)
    no_depth = empty_pixels(depth, holes, max_depth).reshape(-1)
    return BackgroundEstimate(
        estimate.empty_sum + rgb[no_depth].sum(0), estimate.empty_count + int(no_depth.sum()),
        estimate.all_sum + rgb.sum(0), estimate.all_count + rgb.shape[0],
    )


def colour(estimate: BackgroundEstimate) -> np.ndarray:
    """The background colour ``[3]`` (float32): the mean over depth-less pixels where
    enough were seen, else the mean over all pixels, else black (nothing seen yet)."""
    if estimate.all_count == 0:
        return np.zeros(3, np.float32)
    if estimate.empty_count >= MIN_EMPTY_FRACTION * estimate.all_count:
        return (estimate.empty_sum / estimate.empty_count).astype(np.float32)
    return (estimate.all_sum / estimate.all_count).astype(np.float32)


def parse_background(text: str) -> np.ndarray | None:
    """``"auto"`` -> None (estimate it from the data); ``"R,G,B"`` (each in [0, 1]) -> [3]."""
    if text.strip().lower() == "auto":
        return None
    try:
        values = np.array([float(v) for v in text.split(",")], np.float32)
    except ValueError:
        values = np.zeros(0)
    if values.shape != (3,) or not np.all((values >= 0) & (values <= 1)):
        raise ValueError(f"background must be 'auto' or R,G,B with each in [0, 1] "
                         f"(e.g. 1,1,1 for white), got {text!r}")
    return values
