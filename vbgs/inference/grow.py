"""Stream initialisation: components are allocated as data arrive, nothing is read ahead.

A continual learner knows only the batches that have arrived. Here the model keeps
its fixed capacity K (static shapes, see :mod:`vbgs.inference.model`) but starts with every
slot **empty**: an empty slot has a negligible Dirichlet concentration
``alpha = EMPTY_ALPHA`` (so ``E[log pi_k] ~ -1/EMPTY_ALPHA`` and it takes no
responsibility) and sits far outside the data (so the sparse E-step never picks it
as a candidate). Before each batch is learned, :func:`grow` fills empty slots:

* space is cut into squares (2-D) or cubes (3-D) of side ``cell`` about the model's
  origin; a point is **poorly explained** when no active component's mean lies in
  its cell: the current model has nothing there (new ground);
* every such cell gets one new component, placed on one of its points chosen at
  random under ``key`` (prior spatial and colour means = that point), with the prior
  strengths of :func:`vbgs.inference.model.make_prior` at cell length ``ell = cell``;
* then, if ``refine > 0``, ground already covered is refined: the same rule at cells
  of side ``cell / 2^l`` (l = 1 .. levels-1, coarse first), spending at most the share
  ``refine`` of the empty slots per batch, so slots stay for new ground later;
* at most ``max_new`` slots per batch (the bounded rate), never more than the empty
  slots left (the budget K).

The origin is the centre of the first batch's box (a frame for precision) and the
cell side is fixed on the first batch by :func:`calibrate`: the area the batch covers
(:func:`covered_area`) over the number of components it should get. No bounds of
unseen data are read. The state's prior changes as it grows, so under prior
assignment the posterior is no longer independent of the order (as with
:mod:`vbgs.inference.reassign`). The stream loop that grows and learns each batch is
:func:`vbgs.mapping.update_points` (a map started without a prior).
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference import cells, pixel_patches, quadric
from vbgs.inference.cells import cell_index, cell_keys  # noqa: F401  (grow's names before)
from vbgs.inference.model import (
    Mixture,
    PriorConfig,
    State,
    _make_prior,  # compiled make_prior
    check_points_host,
    m_step,
    start,
)

# Compiled: eager, their many small ops dispatch one by one (m_step ~0.1 s at K=20k) and
# each op is one more executable for a new process to load.
_m_step = jax.jit(m_step)
_start = jax.jit(start, static_argnames=("config",))

# Concentration of an empty slot: E[log pi] = digamma(1e-6) ~ -1e6, no responsibility.
EMPTY_ALPHA = 1e-6
# Empty slots sit this many cells from the origin (beyond any data the first batch
# suggests), each one cell further along the first axis, so KD-trees stay balanced.
EMPTY_DISTANCE_CELLS = 1e4
# The most components one batch may add, as a share of the capacity K (the bounded rate).
MAX_NEW_SHARE = 0.5
# Cell levels (each half the side of the one before) that refinement may use.
LEVELS = 4
# Batch points whose covariance gives a grown component's surface normal (the component's
# point and its nearest neighbours in the batch: a 3x3 patch of pixels and a few more).
NORMAL_NEIGHBOURS = 12
# Points farther than this many level-0 cells from every component are beyond the
# model's reach (see reach_of): more than the cell diagonal sqrt(3), so ground the rule
# has covered (a component in the point's own cell) is always within reach. Chosen on
# validation views: results/tuning/reach (python -m experiments.run tune --scene object
# room walk --grid growth.reach_cells=1.5,2,3 --out results/tuning/reach): 1.5, 2 and 3
# are within 0.01 dB of each other (re-made at the code in the table's first line), so 2
# is kept (confirmed, not re-chosen).
REACH_CELLS = 2.0
# Coarse levels far ground may use (point_levels): cells up to 2^5 = 32 times the
# level-0 side, for ground seen 32 times more coarsely than the first frame's median
# (a street's end 30 units away against 1 unit in front of the camera).
COARSE_LEVELS = 5
# Ground seen this many times more coarsely than the first frame's median point starts
# the coarse cells (point_levels): a room's far wall, 2x its median depth, keeps the
# fine cells; a street's end, 10x, does not. Rule: the best mean validation PSNR over the
# object, room and walk, results/tuning/growth/mean.md (made by the command in it, with
# merging on and off): 4 the best.
COARSE_FROM = 4.0
# components="auto": a refinement cell is at least this many pixel footprints a side
# (vbgs.mapping.splits; a component need not be much finer than the pixels it is seen
# with). Half a footprint: 60 views of a surface resolve it below one view's pixel. On
# validation views (128 px, 60 frames, gain 1, no bound merges; vbgs.components) 0.5
# against 1: object 26.38 / 25.83 dB, room 24.09 / 23.74, with about twice the components.
REFINE_FOOTPRINTS = 0.5
# Measured points: the cells a point is looked up in reach this many sigma of its noise
# along its ray, before and behind it (see _pick). Checked on validation views (object,
# 128 px / 20k / 60 frames, the Kinect's own noise and holes, quadric seeds): 1: 24.17 dB,
# 2: 24.47, 3: 24.09.
NOISE_SIGMAS = 2.0
# Measured points: a grown component's seed is moved along its ray onto the quadric of its
# patch, at most this many sigma of its noise (seeds_on_patches). Chosen on validation
# views (object, 128 px / 20k / 60 frames, Kinect noise without holes, 24 neighbours;
# a one-off script setting this constant, not a tune grid: not a Config field yet):
# 1.5: 24.20 dB, 3: 24.33, 6: 24.31. With the quadric of vbgs.inference.quadric (object,
# the Kinect's own noise and holes, validation views): 1.5: 24.06, 3: 24.47, 6: 24.36.
SEED_SIGMAS = 3.0
# Measured points: neighbours in the patch that gives a grown component's normal and seed
# plane (more than NORMAL_NEIGHBOURS: the noise along the rays must average out). Same
# validation views: 12: 23.68 dB, 24: 24.33, 48: 24.45, 96: 23.94 (exact depth 26.58;
# seeded on the noisy point itself: 22.89). With the quadric of vbgs.inference.quadric
# (object, Kinect's own noise and holes, validation views): 24: 23.95, 48: 24.47, 96: 24.49.
NOISY_NORMAL_NEIGHBOURS = 48

class GrowInfo(NamedTuple):
    n_new: int  # components allocated by this call
    n_ground: int  # of which on new ground (level-0 cells without a component)
    n_active: int  # active components after the call
    slots: np.ndarray  # [n_new] the slots filled (the rows of the prior that changed)


# A slot whose concentration exceeds this holds a component (empty slots have EMPTY_ALPHA).
ACTIVE_ALPHA = 10 * EMPTY_ALPHA


def is_active(prior: Mixture) -> np.ndarray:
    """``[k]`` bool: slots holding a component (not empty)."""
    return np.asarray(prior.alpha) > ACTIVE_ALPHA


def mean_spacing(prior: Mixture) -> float:
    """The median distance from an active component's mean to the nearest other one: the
    spacing of a fixed reference's components (a grown one's is its rule's cell)."""
    from vbgs.inference.candidates import means_tree  # scipy, imported when used

    means = np.asarray(prior.space.mean, np.float64)[is_active(prior)]
    if len(means) < 2:
        return 1.0
    dist, _ = means_tree(means).query(means, k=2)
    return float(np.median(dist[:, 1])) or 1.0


def covered_area(xyz) -> float:
    """The area the points ``xyz [n, d]`` cover: ``n s^2`` with ``s`` the median distance
    from a point to its nearest neighbour (each point owns an ``s x s`` patch: exact for
    pixels on a grid; the data are taken to be 2-D, an image or the surfaces a depth
    camera sees)."""
    pts = np.asarray(xyz, np.float64)
    if len(pts) < 2:
        return 1.0
    spacing = lattice_step(pts)
    if spacing is None:
        from scipy.spatial import cKDTree  # 0.2-0.4 s to import: only off the lattice

        dist, _ = cKDTree(pts).query(pts, k=2, workers=-1)
        spacing = float(np.median(dist[:, 1]))
    return len(pts) * spacing**2 if spacing > 0 else 1.0


def lattice_step(pts: np.ndarray) -> float | None:
    """Every point's nearest-neighbour distance when ``pts [n, d]`` (float64) are a full
    axis-aligned lattice, each node once (an image's pixel centres), else None.

    On such a lattice the nearest neighbour is one step along the axis of the smallest
    step (the neighbour differs in that coordinate only, by exactly the step that
    ``np.diff`` finds), so the distance is ``sqrt(step^2) = step`` bit for bit: what a
    KD-tree query returns, without the tree."""
    axes = [np.unique(pts[:, j]) for j in range(pts.shape[1])]
    if math.prod(len(a) for a in axes) != len(pts):
        return None
    steps = [np.diff(a) for a in axes if len(a) > 1]
    if not steps or any((s != s[0]).any() for s in steps):
        return None  # a single point's repeats, or uneven steps
    if len(np.unique(pts, axis=0)) != len(pts):
        return None  # repeated points: n nodes, yet not all of them
    return float(min(s[0] for s in steps))


def empty_prior(n_components: int, origin, cell: float, config: PriorConfig = PriorConfig(),
                dtype=jnp.float32) -> Mixture:
    """A prior of ``n_components`` empty slots about ``origin [d]`` at cell length
    ``cell`` (the prior strengths a filled slot takes). The means are summed on the
    host (the same float32 sum as on the device) and arrays are put, not converted:
    every eager ``jnp`` conversion or op is one more executable a fresh process loads.
    The last few are kept (a stream merging every frame asks for the same one: 18 ms at
    100k slots); a prior's arrays are immutable, so the same one is handed out again."""
    dtype = np.dtype(dtype)
    origin = np.asarray(origin, dtype)
    key = (n_components, origin.tobytes(), dtype.str, float(cell), config)
    if key not in _EMPTY_PRIORS:
        if len(_EMPTY_PRIORS) >= EMPTY_PRIORS_KEPT:
            del _EMPTY_PRIORS[next(iter(_EMPTY_PRIORS))]
        _EMPTY_PRIORS[key] = _empty_prior(n_components, origin, cell, config, dtype)
    return _EMPTY_PRIORS[key]


# The empty priors empty_prior keeps, oldest first (a stream uses one per capacity).
EMPTY_PRIORS_KEPT = 4
_EMPTY_PRIORS: dict = {}


def _empty_prior(n_components: int, origin: np.ndarray, cell: float, config: PriorConfig,
                 dtype: np.dtype) -> Mixture:
    """:func:`empty_prior`, made."""
    d = origin.shape[0]
    offset = np.zeros((n_components, d))
    offset[:, :] = EMPTY_DISTANCE_CELLS * cell
    offset[:, 0] += cell * np.arange(n_components)
    means = origin + offset.astype(dtype)
    prior = _make_prior(means, np.zeros((n_components, 3), dtype), origin, cell, config)
    return prior._replace(alpha=jax.device_put(np.full((n_components,), EMPTY_ALPHA, dtype)))


def start_empty(xyz, n_components: int, cell: float,
                config: PriorConfig = PriorConfig()) -> State:
    """The state before any data: every slot empty, origin at the centre of the first
    batch's box ``xyz [n, d]`` (a frame for precision, nothing more)."""
    return _start(_empty_about(xyz, n_components, cell, config), config)


def _empty_about(xyz, n_components: int, cell: float, config: PriorConfig) -> Mixture:
    """:func:`empty_prior` about the centre of ``xyz``'s box, in ``xyz``'s dtype."""
    pts = np.asarray(xyz)
    dtype = jax.dtypes.canonicalize_dtype(pts.dtype)  # as jnp.asarray(xyz) would hold it
    pts = pts.astype(np.float64)
    origin = 0.5 * (pts.min(0) + pts.max(0))
    return empty_prior(n_components, origin, cell, config, dtype)


def local_normals(x: np.ndarray, chosen: np.ndarray, neighbours: int = NORMAL_NEIGHBOURS,
                  pixel: pixel_patches.PixelGrid | None = None) -> np.ndarray:
    """Unit surface normals ``[m, 3]`` at the points ``x[chosen]`` of a batch ``x [n, 3]``:
    the eigenvector of the smallest eigenvalue of the covariance of each point's
    ``neighbours`` nearest batch points (local PCA; the sign is arbitrary, as a normal's
    is in a covariance). With the frame's ``pixel`` grid the neighbours are those of a
    window about the point's pixel (:mod:`vbgs.inference.pixel_patches`; a window that
    tells no plane gives the viewing ray). Measured points take :func:`seeds_on_patches`
    instead."""
    if pixel is None:
        return quadric.patch_axes(quadric.patches(x, chosen, neighbours))[:, :, 0]
    normal, count = pixel_patches.over_windows(_window_normals, x, chosen, pixel, neighbours)
    few = count < quadric.PLANE_MIN_POINTS
    return np.where(few[:, None], pixel_patches.view_normals(x, chosen, pixel), normal)


def seeds_on_patches(x: np.ndarray, chosen: np.ndarray, ray: np.ndarray,
                     neighbours: int | None = None,
                     pixel: pixel_patches.PixelGrid | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Measured points: the normals ``[m, 3]`` of the surfaces about ``x[chosen]`` and the
    seeds ``[m, 3]``, each chosen point slid along its ray ``u`` onto the quadric fitted
    to its ``neighbours`` nearest batch points (:mod:`vbgs.inference.quadric`), by at
    most ``SEED_SIGMAS`` of its noise. With the frame's ``pixel`` grid the neighbours are
    those of a window about the point's pixel (:mod:`vbgs.inference.pixel_patches`,
    gathered and fitted on the device a chunk of seeds at a time); a window that tells
    no plane leaves its seed at the measured point, its normal along the ray.

    Why: a grown component's prior mean is the reference that, under prior assignment,
    places every later point's latent surface point (:func:`vbgs.inference.candidates.
    candidate_latent`): seeded on one noisy point it sits a sensor sigma off the surface
    (2.6 cm at 4 m for a Kinect), which the latent points then inherit as in-plane
    displacement at oblique views; the fitted surface averages ``neighbours`` points."""
    neighbours = NOISY_NORMAL_NEIGHBOURS if neighbours is None else neighbours
    if pixel is None:
        normal, height = quadric.quadric_patches(x, chosen, neighbours, ray)
        t = np.asarray(quadric.ray_steps(normal, height, ray[chosen]), np.float64)
        unit = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    else:
        unit, t = (np.asarray(a, np.float64) for a in pixel_patches.over_windows(
            _window_seeds, x, chosen, pixel, neighbours, ray))
    t = np.clip(t, -SEED_SIGMAS, SEED_SIGMAS)
    return unit, np.asarray(x, np.float64)[chosen] + t[:, None] * ray[chosen]


@partial(jax.jit, static_argnames="wanted")
def _window_normals(im, at, reach, off, wanted: int):
    """The normals ``[c, 3]`` of the windows' patches at ``at [c]`` and their points'
    counts ``[c]`` (:func:`vbgs.inference.pixel_patches.nearest`)."""
    _, gap, w = pixel_patches.nearest(im, at, reach, off, wanted)
    return quadric.axes(gap, None, w)[:, :, 0], w.sum(1)


@partial(jax.jit, static_argnames="wanted")
def _window_seeds(im, at, reach, off, wanted: int):
    """The unit normals ``[c, 3]`` of the quadrics of the windows' patches at ``at [c]``
    and the steps ``[c]`` along their points' rays onto them (unclipped)."""
    pix, gap, w = pixel_patches.nearest(im, at, reach, off, wanted)
    ray = im.noise[at]
    normal, height = quadric.fit(gap, im.noise[pix], w, ray)
    unit = normal / jnp.sqrt((normal * normal).sum(1, keepdims=True))
    return unit, quadric.ray_steps(normal, height, ray)


def surface_scales(s, normals: np.ndarray, thickness: float) -> np.ndarray:
    """NIW scale matrices ``[m, 3, 3]``: the isotropic ``s I`` (``s`` a scalar or ``[m]``)
    flattened along ``normals [m, 3]``, ``s (I - n n^T + thickness^2 n n^T)``."""
    outer = np.einsum("mi,mj->mij", normals, normals)
    s = np.asarray(s, np.float64)[..., None, None]  # a scalar, or one per component [m]
    return s * (np.eye(normals.shape[1]) - (1.0 - thickness**2) * outer)


def _fill(prior: Mixture, slots: np.ndarray, x_new, c_new, alpha: float,
          scales=None) -> Mixture:
    """Put components on centred positions ``x_new [m, d]`` with colours ``c_new [m, 3]``
    (and NIW scale matrices ``scales [m, d, d]`` when given) into the empty ``slots
    [m]`` (on the host: m changes from batch to batch, and a device scatter would
    compile once per m)."""

    def put(a, rows):
        out = np.array(a)
        out[slots] = rows
        return jax.device_put(out)  # jnp.asarray would compile a copy per shape

    if scales is not None:
        prior = prior._replace(space=prior.space._replace(scale=put(prior.space.scale, scales)))
    space = prior.space._replace(mean=put(prior.space.mean, x_new))
    colour = prior.colour._replace(mean=put(prior.colour.mean, c_new))
    return prior._replace(space=space, colour=colour, alpha=put(prior.alpha, alpha))


class Growth(NamedTuple):
    """The growth rule's settings, fixed on the first batch (hyperparameters, not state).

    cell: side of the level-0 cells (new ground);
    levels: cell sides ``cell / 2^l`` for l < levels (finer levels refine);
    refine: share of the empty slots that refinement (levels >= 1) may take per batch;
    max_new: the most components one batch may add (the bounded rate);
    coarse, footprint, coarse_from: see :func:`point_levels` (far ground, seen coarsely,
        gets coarse cells).
    """

    cell: float
    levels: int
    refine: float
    max_new: int
    coarse: int = 0  # coarse levels far ground may use (cell * 2^j, j <= coarse)
    footprint: float = 0.0  # the first batch's median pixel footprint (0: not given)
    coarse_from: float = 4.0  # footprints this many times the median's start coarse cells


def point_levels(rule: Growth, footprint) -> np.ndarray | None:
    """``[n]`` int: the coarse level of each point, whose pixel footprint (the side of
    the patch of surface its pixel sees, :func:`vbgs.mapping.measurement.point_footprints`)
    is ``footprint [n]``. A component need not be finer than the pixels it is seen
    with: a point seen ``r >= rule.coarse_from`` times more coarsely than the first
    batch's median point is new ground only where no component lies in its cell of side
    ``cell * 2^j``, ``j = 1 + floor(log2(r / coarse_from))`` (at most ``rule.coarse``),
    so far ground (a street's end, a field) takes a few components where near ground
    takes many. None without footprints or coarse levels."""
    if footprint is None or rule.coarse <= 0 or not rule.footprint > 0:
        return None
    ratio = np.asarray(footprint, np.float64) / (rule.footprint * rule.coarse_from)
    level = 1.0 + np.floor(np.log2(np.maximum(ratio, 0.5)))
    return np.clip(level, 0, rule.coarse).astype(np.int64)


def reach_of(rule: Growth, cells: float = REACH_CELLS) -> float:
    """``cells x cell`` (:data:`REACH_CELLS` by default): how far from every component a point may lie and still be
    learned. Once the budget K is spent, new ground gets no component; its points, forced
    onto the nearest components (responsibilities sum to one at any distance), would
    stretch them across the gap into needles (measured on the room: after frame 25 of
    60, up to half of each frame's points lay over 2 cells from every component), so
    the stepper leaves them out (:class:`vbgs.inference.stepper.Stepper`, ``reach``)."""
    return cells * rule.cell


def calibrate(xyz, n_components: int, first_cells: float, *, refine: float = 0.0,
              levels: int = LEVELS, rate: float = MAX_NEW_SHARE, footprint=None,
              coarse: int = 0, coarse_from: float = COARSE_FROM) -> Growth:
    """The rule for a stream whose first batch ``xyz [n, d]`` should get about
    ``first_cells`` level-0 components: the cell side is ``sqrt(A / first_cells)`` for
    the area ``A`` the batch covers (:func:`covered_area`); at most ``ceil(rate * K)``
    new components per batch. ``footprint [n]``: the points' pixel footprints, whose
    median is the reference of far ground's coarse cells (:func:`point_levels`, at most
    ``coarse`` levels, from ``coarse_from`` times the median); when the batch has such
    points the area no longer tells the count, and the side is the one that gives the
    batch ``first_cells`` cells of new ground, counted."""
    first_cells = float(min(max(first_cells, 1.0), n_components))
    if not 0 < rate <= 1:
        raise ValueError(f"the growth rate must be in (0, 1] of the capacity, got {rate!r}")
    if not 0 <= refine <= 1:
        raise ValueError(f"the refinement share must be in [0, 1], got {refine!r}")
    cell = float(np.sqrt(covered_area(xyz) / first_cells))
    reference = 0.0 if footprint is None else float(np.median(footprint))
    rule = Growth(cell, int(levels), float(refine), int(np.ceil(rate * n_components)),
                  int(coarse), reference, float(coarse_from))
    point_level = point_levels(rule, footprint)
    if point_level is None or not point_level.any():
        return rule
    # the side that gives the batch first_cells cells of new ground, counted (by
    # bisection in log(cell): the count falls as the side grows; a dozen halvings of a
    # factor-of-4 bracket: within 0.1%); the levels depend on footprints only
    x = np.asarray(xyz, np.float64)
    x = x - 0.5 * (x.min(0) + x.max(0))
    order, none = np.arange(len(x)), np.zeros((0, x.shape[1]))

    def count(side: float) -> int:
        return len(new_ground(x, none, rule._replace(cell=side), order, len(x), None,
                              point_level))

    lo, hi, step = math.log(cell / 4.0), math.log(cell * 4.0), math.log(4.0)
    for _ in range(8):  # widen the bracket until it holds the side
        if count(math.exp(hi)) < first_cells:
            break
        lo, hi = hi, hi + step
    for _ in range(8):
        if count(math.exp(lo)) >= first_cells:
            break
        lo, hi = lo - step, lo
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if count(math.exp(mid)) < first_cells else (mid, hi)
    return rule._replace(cell=math.exp(hi))


def host_rng(key: jax.Array) -> np.random.Generator:
    """A numpy generator seeded by ``key`` (host-side choices whose sizes change from
    batch to batch would compile a device kernel per size)."""
    return np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel().tolist())


# _pick reads prefixes of the order of this many times its quota, then this many times
# that, while a prefix is at most half the points, before it reads them all. Growth's
# refinement at 640x480 finds its quota's cells in the first 2 to 3.4 times as many
# points (the walk: 300 to 3000 seeds of 50-60k points, a one-off count), where a pass
# over every point took 6-10 ms; a prefix that falls short costs at most half a pass.
PREFIX_TIMES = 8


def _pick(x: np.ndarray, taken: np.ndarray, cell: float, order: np.ndarray,
          quota: int, ray: np.ndarray | None = None) -> np.ndarray:
    """Up to ``quota`` points of ``x [n, d]`` (indices), one per cell of side ``cell``
    that holds none of ``taken [m, d]``, cells taken in the random ``order [n]``.

    ``ray [n, d]``: measured points' noise along their rays. A point counts as new
    ground only if its cell is empty at ``x - NOISE_SIGMAS u`` and ``x + NOISE_SIGMAS u``
    too: noise scatters a surface's points into the cells before and behind it along
    the rays, and a component there already explains them (the budget is not spent on
    the noise).

    A quota under the points (refinement's seeds) is first looked for among the first
    ``PREFIX_TIMES x quota`` points of the order, then ``PREFIX_TIMES`` times as many,
    while that is at most half the points: the first ``quota`` cells found in a prefix
    are the first of the whole order, so the answer is the same; only when the prefixes
    hold too few are all the points read."""
    if quota <= 0 or len(x) == 0:
        return np.zeros(0, np.int64)
    prefix = PREFIX_TIMES * quota
    while 2 * prefix <= len(order):
        part = order[:prefix]
        got = _first_cells(x.take(part, 0), taken, cell, np.arange(len(part)), quota,
                           None if ray is None else ray.take(part, 0))
        if len(got) == quota:
            return part[got]
        prefix *= PREFIX_TIMES
    return _first_cells(x, taken, cell, order, quota, ray)


def _first_cells(x: np.ndarray, taken: np.ndarray, cell: float, order: np.ndarray,
                 quota: int, ray: np.ndarray | None) -> np.ndarray:
    """:func:`_pick` over the points ``x`` in ``order``: the first point of each of the
    first ``quota`` empty cells."""
    return _first_of_cells(*_empty_cells(x, taken, cell, ray), order, quota)


def _empty_cells(x: np.ndarray, taken: np.ndarray, cell: float, ray: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The cells of side ``cell`` of the points ``x [n, d]`` as keys ``[n]`` (equal
    exactly where the cells are) and ``[n]`` bool: the cell holds none of ``taken [m,
    d]``, nor do those a step of noise before and behind the point (``ray``, :func:`_pick`)."""
    shifted = [x] if ray is None else [x, x - NOISE_SIGMAS * ray, x + NOISE_SIGMAS * ray]
    (taken_keys, *point_keys), size = cells.box_keys([taken, *shifted], cell)
    point_keys = np.stack(point_keys)  # [shifts, n]
    return point_keys[0], ~cells.held(taken_keys, point_keys, size).any(0)


def _first_of_cells(keys: np.ndarray, empty: np.ndarray, order: np.ndarray, quota: int
                    ) -> np.ndarray:
    """Of the points ``order`` (indices into ``keys`` and ``empty``), the first of each of
    the first ``quota`` cells that are empty."""
    poor = order[empty[order]]  # points in empty cells, in random order
    _, first = np.unique(keys[poor], return_index=True)  # one point per cell
    return poor[np.sort(first)][:quota]


def _present(levels: np.ndarray) -> np.ndarray:
    """The levels among ``levels [n]`` (whole numbers >= 0), ascending: ``np.unique``'s
    answer, 10x faster."""
    return np.flatnonzero(np.bincount(levels))


class Ground(NamedTuple):
    """A batch's new ground against the components in use, found once
    (:func:`ground_of`) and then picked from in any order (:func:`new_ground`)."""

    keys: np.ndarray  # [n] int64: each point's cell at its level (equal within a level
    #                   exactly where the cells are)
    empty: np.ndarray  # [n] bool: the cell is new ground (as _pick tests it)
    levels: np.ndarray | None  # [n] each point's level; None: all at level 0
    n_cells: int  # the new-ground cells of all levels: what new_ground takes at most


def ground(x: np.ndarray, taken: np.ndarray, rule: Growth, ray: np.ndarray | None = None,
           levels: np.ndarray | None = None) -> Ground:
    """The new ground of the points ``x [n, d]`` against the means ``taken [m, d]``
    (:func:`new_ground`'s arguments), for :func:`new_ground` to pick from in any order
    with the same answer as it finds alone. Why it can: level by level, finest first,
    :func:`new_ground` holds the cells of the points it chose at the finer levels; a
    point chosen in a cell of side ``c`` lies in the one cell of side ``c 2^j`` that
    holds that cell (the grids share the origin, and dividing by a power of two is exact
    in floating point), whichever of the cell's points was chosen. So the cells held at
    each level do not depend on the order, as long as no quota is reached at a finer
    level, and after one is reached nothing is picked. Each level here holds one point
    of each of the finer levels' new cells."""
    if levels is None:
        keys, empty = _empty_cells(x, taken, rule.cell, ray)
        return Ground(keys, empty, None, len(np.unique(keys[empty])))
    keys, empty = np.zeros(len(x), np.int64), np.zeros(len(x), bool)
    held = [taken]
    for level in _present(levels):
        here = np.flatnonzero(levels == level)
        keys[here], empty[here] = _empty_cells(
            x.take(here, 0), np.concatenate(held), rule.cell * 2.0**level,
            None if ray is None else ray.take(here, 0))
        new = here[empty[here]]
        _, first = np.unique(keys[new], return_index=True)
        held.append(x.take(new[first], 0))
    return Ground(keys, empty, levels, sum(len(h) for h in held[1:]))


def new_ground(x: np.ndarray, taken: np.ndarray, rule: Growth, order: np.ndarray,
               quota: int, ray: np.ndarray | None = None, levels=None,
               found: Ground | None = None) -> np.ndarray:
    """Up to ``quota`` points of ``x [n, d]`` (indices), one per cell holding none of the
    means ``taken [m, d]``: level-0 cells, or with ``levels [n]`` (:func:`point_levels`)
    each point's own coarse cell, finest level first (a component placed on near
    ground takes the coarse cell it lies in). ``found``: the :func:`ground` of these
    arguments, picked from in ``order`` (the same answer)."""
    if found is not None:
        return _picked(found, order, quota)
    if levels is None:
        return _pick(x, taken, rule.cell, order, quota, ray)
    chosen = np.zeros(0, np.int64)
    present = _present(levels)
    if len(present) == 1:  # one level (near ground alone): the points as they are
        return _pick(x, taken, rule.cell * 2.0 ** present[0], order, quota, ray)
    for level in present:
        if quota - len(chosen) <= 0:
            break
        here = order[levels[order] == level]  # this level's points, in the random order
        # rows gathered by take: 4x faster than x[here] at 300k rows (a 640x480 frame)
        picked = _pick(x.take(here, 0), np.concatenate([taken, x.take(chosen, 0)]),
                       rule.cell * 2.0**level, np.arange(len(here)), quota - len(chosen),
                       None if ray is None else ray.take(here, 0))
        chosen = np.concatenate([chosen, here[picked]])
    return chosen


def _picked(found: Ground, order: np.ndarray, quota: int) -> np.ndarray:
    """:func:`new_ground`'s answer from its :func:`ground`: up to ``quota`` points, the
    first of each new cell in ``order``, finest level first."""
    if found.levels is None:
        return _first_of_cells(found.keys, found.empty, order, quota)
    chosen = [np.zeros(0, np.int64)]
    left = quota
    for level in _present(found.levels):
        if left <= 0:
            break
        here = order[found.levels[order] == level]  # this level's points, in the order
        chosen.append(_first_of_cells(found.keys, found.empty, here, left))
        left -= len(chosen[-1])
    return np.concatenate(chosen)


def select(x: np.ndarray, taken: np.ndarray, n_empty: int, rule: Growth, *,
           key: jax.Array, ray: np.ndarray | None = None, levels=None, earns=None
           ) -> tuple[np.ndarray, int]:
    """Where a batch adds components: indices into ``x [n, d]`` (positions about the
    grid's origin) given the means ``taken [m, d]`` of the components in use and
    ``n_empty`` free slots. First one per cell holding no component (new ground,
    :func:`new_ground`), then refinement at finer levels within its share of the slots
    left; at most ``rule.max_new`` in all; random choices under ``key``. ``earns [n,
    rule.levels]`` bool: the refinement levels each point may seed
    (:func:`vbgs.mapping.splits.earned_levels`); None: every point, every level. Returns
    ``(indices, n_ground)``."""
    chosen, n_ground, _ = _select(x, taken, n_empty, rule, key=key, ray=ray, levels=levels,
                                  earns=earns)
    return chosen, n_ground


def _select(x: np.ndarray, taken: np.ndarray, n_empty: int, rule: Growth, *,
            key: jax.Array, ray=None, levels=None, earns=None, found: Ground | None = None
            ) -> tuple[np.ndarray, int, np.ndarray]:
    """:func:`select`, and the refinement level of each chosen point ``[m]`` (0: new
    ground); ``found``: :func:`new_ground`'s."""
    order = host_rng(key).permutation(len(x))  # random order of the points
    budget = int(min(rule.max_new, n_empty))
    chosen = new_ground(x, taken, rule, order, budget, ray, levels, found)
    n_ground = len(chosen)
    refine = int(min(budget - n_ground, np.floor(rule.refine * (n_empty - n_ground))))
    level_of = [np.zeros(n_ground, np.int64)]
    for level in range(1, rule.levels):
        if refine <= 0:
            break
        seeds = order if earns is None else order[earns[order, level]]
        more = _pick(x, np.concatenate([taken, x[chosen]]), rule.cell / 2**level, seeds,
                     refine, ray)
        chosen = np.concatenate([chosen, more])
        level_of.append(np.full(len(more), level, np.int64))
        refine -= len(more)
    return chosen, n_ground, np.concatenate(level_of)


def grow(state: State, xyz, rgb, rule: Growth, *, key: jax.Array,
         config: PriorConfig = PriorConfig(), ray=None, levels=None, earns=None,
         pixel: pixel_patches.PixelGrid | None = None, held=None,
         found: Ground | None = None) -> tuple[State, GrowInfo]:
    """Fill empty slots on the poorly explained points of the batch ``xyz [n, d]``,
    ``rgb [n, 3]`` (see the module docstring and :func:`select`), deterministic under
    ``key``; ``ray [n, 3]``: measured points' noise along their rays (:func:`local_normals`);
    ``levels [n]``: the points' coarse levels (:func:`point_levels`); ``earns [n, levels]``:
    the refinement levels each point may seed (:func:`vbgs.mapping.splits.earned_levels`);
    ``pixel``: a frame's points on its pixel grid, where the seeds' patches are found
    (:mod:`vbgs.inference.pixel_patches`; None: bare points, a KD-tree over the batch);
    ``held [g, d]``: positions about the grid's origin whose cells count as held though
    no component's mean lies there (a component's seed after its mean moved away, ground
    a merge emptied: ``vbgs.mapping.mapper._held``); ``found``: the batch's new ground
    against this state, ``held`` and ``levels``, found already (:func:`ground_of`, for
    :func:`shortfall`), or None."""
    prior, info = _grown_prior(state.prior, state.posterior, xyz, rgb, rule, key=key,
                               config=config, ray=ray, levels=levels, earns=earns,
                               pixel=pixel, held=held, found=found)
    if info.n_new == 0:
        return state, info
    return state._replace(prior=prior, posterior=_m_step(prior, state.stats)), info


def _about_origin(prior: Mixture, posterior: Mixture, xyz, ray=None, held=None):
    """The batch ``xyz [n, d]`` about the grid's origin ``[n, d]``, the means of the
    components in use ``[m, d]`` (of ``posterior``; with ``held [g, d]`` after them:
    positions whose cells count as held), the active slots ``[k]`` bool and the rays
    ``[n, d]`` (or None), in float64 on the host."""
    active = is_active(prior)
    x = np.asarray(xyz, np.float64) - np.asarray(prior.origin, np.float64)
    taken = np.asarray(posterior.space.mean, np.float64)[active]
    if held is not None and len(held):
        taken = np.concatenate([taken, np.asarray(held, np.float64)])
    return x, taken, active, None if ray is None else np.asarray(ray, np.float64)


def ground_of(state: State, xyz, rule: Growth, *, ray=None, levels=None, held=None
              ) -> Ground:
    """The new ground (:func:`ground`) of the batch ``xyz [n, d]`` against the components
    of ``state`` in use (and ``held``, as :func:`grow`'s): what :func:`shortfall` counts
    and :func:`grow` picks from, found once for both while nothing changes between."""
    x, taken, _, ray = _about_origin(state.prior, state.posterior, xyz, ray, held)
    return ground(x, taken, rule, ray, levels)


def empty_slots(state: State) -> int:
    """How many slots of ``state`` no component uses (:func:`is_active`)."""
    return int((~is_active(state.prior)).sum())


def short_of_slots(state: State, rule: Growth) -> bool:
    """Whether :func:`shortfall` counts new ground: fewer empty slots than a batch may
    add."""
    return empty_slots(state) < rule.max_new


def shortfall(state: State, xyz, rule: Growth, *, ray=None, levels=None, earns=None,
              held=None, found: Ground | None = None) -> int:
    """How many more components the new ground of the batch ``xyz [n, d]`` wants (at most
    ``rule.max_new``, as :func:`select` counts it) than there are empty slots: above 0
    when the budget is spent (:mod:`vbgs.inference.merge` frees slots for it). With
    ``earns [n, levels]`` (:func:`vbgs.mapping.splits.earned_levels`) the refinement those
    points seed counts too (as :func:`select` counts it with every slot free, in the
    points' own order). Nothing is counted while the empty slots alone take the most a
    batch may add (``rule.max_new``, which bounds what it wants): the shortfall is then
    at most ``rule.max_new - empty slots <= 0``, and that bound is returned. ``held``: as
    :func:`grow`'s; ``found``: the batch's :func:`ground_of` (without ``earns``)."""
    n_empty = empty_slots(state)
    if not short_of_slots(state, rule):
        return rule.max_new - n_empty
    if earns is None:
        if found is None:
            found = ground_of(state, xyz, rule, ray=ray, levels=levels, held=held)
        return min(found.n_cells, rule.max_new) - n_empty
    x, taken, _, ray = _about_origin(state.prior, state.posterior, xyz, ray, held)
    order = np.arange(len(x))
    chosen = new_ground(x, taken, rule, order, rule.max_new, ray, levels)
    for level in range(1, rule.levels):
        quota = rule.max_new - len(chosen)
        if quota <= 0:
            break
        more = _pick(x, np.concatenate([taken, x[chosen]]), rule.cell / 2**level,
                     order[earns[:, level]], quota, ray)
        chosen = np.concatenate([chosen, more])
    return len(chosen) - n_empty


def _grown_prior(prior: Mixture, posterior: Mixture, xyz, rgb, rule: Growth, *,
                 key: jax.Array, config: PriorConfig, ray=None, levels=None, earns=None,
                 pixel: pixel_patches.PixelGrid | None = None, held=None,
                 found: Ground | None = None) -> tuple[Mixture, GrowInfo]:
    """:func:`grow`'s new prior (the components in use are those of ``posterior``)."""
    xyz, rgb = check_points_host(xyz, rgb)  # numpy: jnp.asarray compiles per shape
    x, taken, active, ray = _about_origin(prior, posterior, xyz, ray, held)
    empty = np.flatnonzero(~active)
    chosen, n_ground, split = _select(x, taken, len(empty), rule, key=key, ray=ray,
                                      levels=levels, earns=earns, found=found)
    n_new = len(chosen)
    if n_new == 0:
        return prior, GrowInfo(0, 0, int(active.sum()), empty[:0])
    slots = empty[:n_new]
    dtype = prior.alpha.dtype
    scales = None
    coarse = levels is not None and bool(levels[chosen].any())
    seeds = x[chosen]
    fine = earns is not None and bool(split.any())  # auto's splits: their own cells
    if prior.dim == 3 and (config.surface_thickness != 1.0 or coarse or fine) and len(x) >= 3:
        s = float(np.asarray(prior.space.scale)[slots[0], 0, 0])  # an empty slot's: s I
        if coarse:  # a component on a coarse cell of side cell 2^j: variance 4^j times
            s = s * 4.0 ** levels[chosen]
        if fine:  # a split in a cell of side cell / 2^l: variance 4^-l times
            s = s * 4.0 ** -split.astype(np.float64)
        if pixel is not None:  # the camera centre about the grid's origin, as x is
            pixel = pixel._replace(eye=np.asarray(pixel.eye, np.float64)
                                   - np.asarray(prior.origin, np.float64))
        if ray is None:
            normals = local_normals(x, chosen, pixel=pixel)
        else:  # measured points: seeds on their patches' quadrics
            normals, seeds = seeds_on_patches(x, chosen, ray, pixel=pixel)
        scales = surface_scales(s, normals, config.surface_thickness).astype(dtype)
    new_prior = _fill(prior, slots, seeds.astype(dtype),
                      np.asarray(rgb)[chosen].astype(dtype), float(config.alpha), scales)
    return new_prior, GrowInfo(n_new, n_ground, int(active.sum()) + n_new, slots)


def batch_prior(xyz, rgb, n_components: int, *, key: jax.Array,
                config: PriorConfig = PriorConfig()) -> Mixture:
    """The stream start when one batch ``xyz [n, d]``, ``rgb [n, 3]`` is all there is
    (a batch fit): the grown prior with ``min(K, n)`` components spread over it."""
    rule = calibrate(xyz, n_components, n_components, rate=1.0, refine=1.0)
    empty = _empty_about(xyz, n_components, rule.cell, config)
    # grow from the empty state (posterior = prior), without the state: its start and
    # M-step would be two more executables for a fresh process to load, then dropped
    prior, _ = _grown_prior(empty, empty, xyz, rgb, rule, key=key, config=config)
    return prior
