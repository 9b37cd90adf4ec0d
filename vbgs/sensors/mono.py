"""A monocular depth network's output after alignment to metric depth.

Source: affine-invariant depth networks (Ranftl et al., "Towards Robust Monocular
Depth Estimation: Mixing Datasets for Zero-shot Cross-dataset Transfer", TPAMI 2022)
are trained up to a scale and shift per image, so after one alignment for a whole
sequence each frame keeps a scale and shift error of its own; what they also show, a
smooth low-frequency distortion, depth bled across object boundaries and depth on the
sky, is added as below. The magnitudes (a few per cent) are this model's choice, in the
range such networks' relative errors are reported in, not a fit to one network:

    d_mono(u, v) = s * w(u, v) * bleed(fill(d))(u, v) + t

* ``fill``: a network predicts depth on every pixel, sky and background included:
  pixels without true depth get ``FAR_FACTOR`` (1.5) times the frame's largest depth.
* ``bleed``: depth near depth edges is smeared across the edge: within
  ``BLEED_PX * level`` px of an edge (the 4-neighbour test of
  :func:`vbgs.sensors.holes.depth_edges`) the depth is replaced by its Gaussian blur
  of sigma ``BLEED_PX * level / 2`` px (2 px and 1 px at level 1).
* ``s = 1 + level * SCALE_DRIFT * N(0, 1)``: per-frame scale drift (3 %).
* ``t = level * SHIFT_DRIFT * N(0, 1) * median(d)``: per-frame shift drift (2 % of the
  frame's median depth).
* ``w(u, v) = 1 + level * WARP * sum_k c_k sin(2 pi f_k . (u / W, v / H) + phi_k)``:
  a smooth multiplicative warp, ``WARP_TERMS`` sinusoids of 0.5-1.5 cycles per image
  in random directions, weights ``c`` on the simplex, so ``|w - 1| <= level * WARP``
  (5 %); its RMS is about ``level * WARP / 2``.

There are no holes. Level 0 returns the filled true depth.

That depth is at the sequence's true metric scale: one alignment for the whole sequence,
known exactly, is an oracle that a user's RGB-only stream does not have. A network's own
output knows no metre (affine-invariant networks are trained up to a scale and shift of
their inverse depth), so what a stream is handed is :func:`network_output`: the depth
above as inverse depth in a unit and with an offset of the network's own
(:func:`network_units`, drawn per run). The stream must find the metric scale from the
frames that have arrived, with their poses, as it does for a real network's output
(``depth.stream``: the first frames' multi-view consistency, then each frame aligned to
the frames before it); that is the path ``--simulate-sensor mono --sensor mono`` takes.

What a learner takes as surface (:meth:`Mono.surface`) is less: the far field
(:func:`vbgs.sensors.far_field.far_field`: the sky and empty background a network gives
depth to) and the depth edges of the depth map as given
(:func:`vbgs.sensors.holes.depth_edges`; depth bled across an edge is a steep ramp, so
the test finds the ramp itself) are made depth-less. Left in, the first becomes a shell
of splats around the scene and the second a fringe of splats behind every silhouette.
(Cutting a further band of 1 px around the edges lost more surface than fringe:
docs/validation.md, "vbgs.sensors.mono".)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vbgs.sensors.base import check_depth, check_level
from vbgs.sensors.far_field import far_field
from vbgs.sensors.holes import EDGE_THRESHOLD, HoleSpec, depth_edges, refuse_holes, valid

FAR_FACTOR = 1.5  # depth given to pixels without depth: this times the frame's max depth
SCALE_DRIFT = 0.03  # std of the per-frame scale error
SHIFT_DRIFT = 0.02  # std of the per-frame shift, as a fraction of the median depth
WARP = 0.05  # bound of the multiplicative low-frequency warp
WARP_TERMS = 3
WARP_CYCLES = (0.5, 1.5)  # spatial frequency of each warp term, cycles per image side
BLEED_PX = 2.0  # px smeared across depth edges at level 1
# Share of the RMS error left once each frame is aligned to the frames before it (the
# per-frame alignment of depth.perframe, which every mono frame a learner sees goes
# through): measured 2.7 % against 4.2 % on the object and 3.2 % against 4.8 % on the
# room (64 px, 20 frames, RMS of log(d / d_true) over the surface pixels).
ALIGNED_SHARE = 0.7
UNIT_SPAN = (0.1, 10.0)  # the network's unit of inverse depth: log-uniform in this span
OFFSET_SPAN = (0.0, 1.0)  # its offset, in its units times one inverse metre


def network_units(rng: np.random.Generator) -> tuple[float, float]:
    """A network's unit and offset of inverse depth (``UNIT_SPAN``, ``OFFSET_SPAN``):
    nothing of them is known to whoever reads its output."""
    unit = float(np.exp(rng.uniform(*np.log(UNIT_SPAN))))
    return unit, unit * float(rng.uniform(*OFFSET_SPAN))


def network_output(depth: np.ndarray, unit: float, offset: float) -> np.ndarray:
    """What a network outputs for simulated depth ``depth [h, w]`` (positive on every
    pixel, :meth:`Mono.simulate`): ``unit / depth + offset`` (float64), inverse depth in
    its own unit; ``1 / d = (p - offset) / unit`` is what an alignment must find."""
    depth = np.asarray(depth, np.float64)
    if not np.all(depth > 0):
        raise ValueError("a network's output needs depth on every pixel (mono's simulate "
                         "gives it); this depth has pixels without")
    return unit / depth + offset


def fill_missing(depth: np.ndarray, factor: float = FAR_FACTOR) -> np.ndarray:
    """Depth on every pixel: the missing ones get ``factor`` times the largest depth."""
    ok = valid(depth)
    if not ok.any():
        raise ValueError("mono needs some true depth to place the rest against; this frame "
                         "has none")
    return np.where(ok, depth, factor * np.max(depth[ok]))


def _shift(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """``a`` moved by ``(dy, dx)`` pixels, edge values repeated."""
    h, w = a.shape
    padded = np.pad(a, ((abs(dy),) * 2, (abs(dx),) * 2), mode="edge")
    return padded[abs(dy) - dy: abs(dy) - dy + h, abs(dx) - dx: abs(dx) - dx + w]


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Pixels within ``radius`` (Chebyshev distance) of a True pixel of ``mask``."""
    out = mask.copy()
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            out |= _shift(mask, dy, dx)
    return out


def gaussian_blur(a: np.ndarray, sigma: float) -> np.ndarray:
    """Separable Gaussian blur of ``a [h, w]`` with edge padding (sigma in px)."""
    if sigma <= 0:
        return a.copy()
    radius = int(np.ceil(3 * sigma))
    offsets = np.arange(-radius, radius + 1)
    weights = np.exp(-0.5 * (offsets / sigma) ** 2)
    weights /= weights.sum()
    rows = sum(wk * _shift(a, int(k), 0) for k, wk in zip(offsets, weights, strict=True))
    return sum(wk * _shift(rows, 0, int(k)) for k, wk in zip(offsets, weights, strict=True))


def bleed_edges(depth: np.ndarray, camera=None, level: float = 1.0,
                threshold: float = EDGE_THRESHOLD) -> np.ndarray:
    """Depth blurred (sigma ``BLEED_PX * level / 2`` px) within ``BLEED_PX * level`` px
    of a depth edge, unchanged elsewhere. ``depth`` must have depth on every pixel."""
    radius = int(np.ceil(BLEED_PX * level))
    if radius == 0:
        return depth.copy()
    band = dilate(depth_edges(depth, threshold, camera), radius)
    return np.where(band, gaussian_blur(depth, BLEED_PX * level / 2.0), depth)


def warp_field(shape, rng: np.random.Generator, amplitude: float = WARP) -> np.ndarray:
    """``1 + amplitude * sum_k c_k sin(2 pi f_k . (u / W, v / H) + phi_k)`` ``[h, w]``."""
    h, w = shape
    cycles = rng.uniform(*WARP_CYCLES, WARP_TERMS)
    angle = rng.uniform(0.0, 2 * np.pi, WARP_TERMS)
    phase = rng.uniform(0.0, 2 * np.pi, WARP_TERMS)
    weight = rng.dirichlet(np.ones(WARP_TERMS))
    x = ((np.arange(w) + 0.5) / w)[None, :]
    y = ((np.arange(h) + 0.5) / h)[:, None]
    field = sum(c * np.sin(2 * np.pi * f * (np.cos(a) * x + np.sin(a) * y) + p)
                for c, f, a, p in zip(weight, cycles, angle, phase, strict=True))
    return 1.0 + amplitude * field


@dataclass(frozen=True)
class Mono:
    """A monocular depth network after alignment (see the module docstring for the
    formula): per-frame scale (3 %) and shift (2 % of the median depth) drift, a smooth
    multiplicative warp (up to 5 %), edges bled over 1-2 px, depth on every pixel
    (missing pixels at 1.5 times the frame's largest depth), no holes."""

    name: str = "mono"
    scale_drift: float = SCALE_DRIFT
    shift_drift: float = SHIFT_DRIFT
    warp: float = WARP
    far_factor: float = FAR_FACTOR
    edge_threshold: float = EDGE_THRESHOLD
    aligned_share: float = ALIGNED_SHARE

    def relative_sigma(self, level: float = 1.0) -> float:
        """RMS relative error ``level * sqrt(scale^2 + shift^2 + warp_rms^2)``; the
        warp's mean square is ``warp^2 E[sum c_k^2] / 2 = warp^2 / (WARP_TERMS + 1)``
        for flat Dirichlet weights."""
        warp_rms = self.warp * np.sqrt(1.0 / (WARP_TERMS + 1))
        return check_level(level) * float(np.sqrt(self.scale_drift**2 + self.shift_drift**2
                                                  + warp_rms**2))

    def sigma_z(self, z, camera=None, level: float = 1.0) -> np.ndarray:
        """``aligned_share * relative_sigma(level) * z``: the RMS axial error at depth
        ``z`` that is left once each frame is aligned to the frames before it (the depth
        a learner sees; ``ALIGNED_SHARE``); the shift drift, a fraction of the median
        depth, counted as a fraction of ``z``; edge bleeding, a loss of resolution,
        left out. (The learner scored about the same with the unaligned share:
        docs/validation.md, "vbgs.sensors.mono: sigma_z".)"""
        return self.aligned_share * self.relative_sigma(level) * np.asarray(z, np.float64)

    def surface(self, depth, camera, level: float = 1.0) -> np.ndarray:
        """``depth [h, w]`` (float32) with its far field and its depth edges made
        depth-less (0): the part of a network's depth that is surface (module
        docstring). ``level`` is not read: what is cut depends on the depth alone."""
        check_level(level)
        depth = check_depth(depth, camera)
        cut = far_field(depth) | depth_edges(depth, self.edge_threshold, camera)
        return np.where(cut, 0.0, depth).astype(np.float32)

    def simulate(self, depth, camera, rng: np.random.Generator, level: float = 1.0,
                 hole_spec: HoleSpec = HoleSpec()) -> np.ndarray:
        """Predicted depth ``[h, w]`` float32, positive on every pixel (a depth network
        leaves no holes: ``hole_spec`` must be the sensor's own)."""
        refuse_holes(self.name, hole_spec)
        level = check_level(level)
        depth = check_depth(depth, camera)
        median = float(np.median(depth[valid(depth)])) if valid(depth).any() else 0.0
        filled = bleed_edges(fill_missing(depth, self.far_factor), camera, level,
                             self.edge_threshold)
        scale = 1.0 + level * self.scale_drift * rng.standard_normal()
        shift = level * self.shift_drift * median * rng.standard_normal()
        warp = warp_field(filled.shape, rng, level * self.warp)
        out = scale * warp * filled + shift
        floor = 1e-3 * float(filled.min())  # a large level could push depth below 0
        return np.maximum(out, floor).astype(np.float32)
