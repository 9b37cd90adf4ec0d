"""``components="auto"``: where a component earns a child, by the evidence of the stream.

A point of a batch may seed a child in a finer cell of the growth grid (side
``rule.cell / 2^l``, ``l = 1 .. levels-1``; :func:`vbgs.inference.grow.select`). Whether
the child is worth its place is a Bayesian model comparison between two explanations of
the colours ``c_1 .. c_n`` (``d = 3`` channels) of every point the stream has shown in
that cell so far (:class:`CellColours`, a hashed table of sums over frames):

* ``H0``: the point's component (the active one whose mean is nearest) explains them,
  colour mean ``m`` (its posterior mean, taken as known);
* ``H1``: a child of the cell does, with its own colour mean ``mu ~ N(m, s^2 / lambda_0)``
  (the prior a grown component takes: centred on what explained the cell before,
  ``lambda_0 = prior.colour_strength`` pseudo-points).

Both share the cell's colour noise ``s^2``, which is not the model's ``sigma_c^2``
alone: colour that varies inside the cell (texture finer than the cell, an edge
crossing it) is noise to one child of the cell, which can explain the cell's mean and
nothing finer. Its precision ``1 / s^2`` gets the conjugate Gamma prior with the same
weight as the mean's, ``lambda_0`` pseudo-points of ``d`` channels at variance
``sigma_c^2`` (``a_0 = lambda_0 d / 2``, ``b_0 = a_0 sigma_c^2``; ``sigma_c =
prior.colour_noise``). With ``R_1 = sum |c_i - c_bar|^2`` (the scatter about the cell's
mean ``c_bar``) and ``R_0 = R_1 + n |c_bar - m|^2`` (about ``m``), integrating ``mu`` and
``s^2`` out (Normal-Gamma; the ``2 pi`` and Gamma-function terms are common to both):

    log p(c | H0) = const - (a_0 + n d / 2) log(b_0 + R_0 / 2)
    log p(c | H1) = const - (a_0 + n d / 2) log(b_0 + R_1 / 2 + n lambda_0 |c_bar - m|^2
                                                  / (2 (n + lambda_0)))
                          - (d / 2) log(1 + n / lambda_0)

so the child's log Bayes factor is

    L = (a_0 + n d / 2) log[(b_0 + R_0 / 2) / (b_0 + R_1 / 2 + n lambda_0 |c_bar - m|^2
                                                 / (2 (n + lambda_0)))]
        - (d / 2) log(1 + n / lambda_0).

The last term is the Occam factor of the child's colour mean: it grows with the
evidence (``log n``) while a miss the component makes at the cell grows the first term
linearly in ``n``; a cell whose points scatter as much about ``c_bar`` as ``c_bar`` lies
from ``m`` (texture below the cell's side) earns nothing however many points it holds,
where the rule this replaces (the colour gain of one frame's points, noise fixed at
``sigma_c``: ``n |c_bar - m|^2 / (2 sigma_c^2) > 1`` nat) split every cell of fine
texture, the walk's grass to the 131k ceiling.

The child's other parameters are paid for too, as the streaming bound pays each
component's KL to its prior: on the surfaces a depth camera sees, a child's density
over its cell is what its parent's was there (its weight falls as its area does), so
its spatial likelihood gain is taken as zero, while the Occam factors of its spatial
mean (``kappa_0 = prior.mean_strength`` pseudo-points), covariance (``nu_0 =
prior.cov_strength``) and weight (``alpha = prior.alpha``) remain, each ``1/2 log(1 + n /
strength)`` per free parameter (the Laplace form of the KL of a conjugate posterior from
``n`` points; :func:`spatial_occam`):

    S = (D / 2) log(1 + n / kappa_0) + (D (D + 1) / 4) log(1 + n / nu_0)
        + (1 / 2) log(1 + n / alpha),                      D = 3 spatial dimensions.

A point's cell at level ``l`` earns a child when ``L - S > growth.refine_gain`` (the
prior log odds against a split; 0: the more probable explanation wins), in cells no
finer than ``growth.refine_footprints`` of the point's pixel footprints (a component
need not be much finer than the pixels it is seen with). The sums include the batch
being grown (a cell's evidence is every point it has shown, this frame's too); the
comparison is against the component nearest each point now, so once a child sits in
the cell its own colour answers for it.

**The shape term** (``growth.refine_shape``). Taking the in-plane gain as zero leaves
out where the surface bends or ends (a sphere's curve, a silhouette): there the parent's
Gaussian, fitted flat over a larger patch, misses the cell's points along their normal,
which colour does not see. Write the parent's density (mean ``mu``, expected covariance
``Sigma``) in the cell's own frame, ``u`` the direction in which the cell's points
spread least (their normal: the least eigenvector of their scatter ``S`` about their
mean ``x_bar``) and ``B`` the plane orthogonal to it: ``N(x | mu, Sigma) = N_B(B^T x) x
N(u^T x | conditional mean, v)``, ``v = 1 / (u^T Sigma^-1 u)``. The in-plane factor is
the part taken as equal under both hypotheses (above); the child replaces the
conditional by a plane of its own through the cell's points (normal ``u``, through
``x_bar``) at the same precision ``1 / v`` across it (the child pays for its plane's
parameters in ``S``; crediting it with a tighter spread than the parent's would split
flat ground wherever the parent's posterior is still loose). Summed over the cell's
points, with ``M = S + n (x_bar - mu)(x_bar - mu)^T`` (second moment about ``mu``):

    G = (1/2) [tr(Sigma^-1 M) - tr((B^T Sigma B)^-1 B^T M B) - u^T S u / v]

(the first two terms: the conditional's squared misses, the full quadratic less the
in-plane marginal's; the last: the child's). On a flat patch the parent's plane is the
child's and ``G = 0``; where the surface bends away from the parent's plane the
misses grow with ``n`` and ``G > 0``. The table keeps the sums ``G`` needs per cell
(the offsets of its points from the cell's centre and their outer products), a cell
earns a child when ``L + G - S > growth.refine_gain``, and the component that explains
a point is, of the ``SHAPE_CANDIDATES`` whose means are nearest, the one under whose
Gaussian it is most probable (:func:`explaining`: beside a fold the nearest mean can be
the other surface's).

The table (like :mod:`vbgs.mapping.saturation`'s) has ``2^TABLE_BITS`` slots addressed
by a hash of the cell (its level and integer coordinates); a cell whose slot holds
another is handed the slot and starts again (a collision forgets evidence: a split
later, never a wrong one).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.inference import expfam, grow
from vbgs.inference.model import PriorConfig
import vbgs.mapping.saturation as saturation

# 2^21 slots (56 MiB: keys, counts and colour sums): the fine cells a 128 px stream of
# 60 frames shows at levels 1-3 with few clashes (each only delays a split).
TABLE_BITS = 21
# The shape term's components that may explain a point (explaining): the nearest by mean
# is not the one that explains a point beside a fold or a corner (a wall's point can lie
# nearer a floor component's mean than its own wall's).
SHAPE_CANDIDATES = 8


class CellColours(NamedTuple):
    """Per refinement cell, the colours the stream has shown there: ``cell [T]`` int64
    the cell each slot holds (-1: none), ``count [T]`` points, ``total [T, 3]`` their
    colour sum, ``square [T]`` the sum of their ``|c|^2``; with the shape term
    (``growth.refine_shape``) also ``place [T, 3]``, the sum of the points' offsets from
    their cell's centre, and ``spread [T, 3, 3]``, the sum of the offsets' outer
    products (None without it). Host arrays, replaced (never changed in place) batch by
    batch."""

    cell: np.ndarray
    count: np.ndarray
    total: np.ndarray
    square: np.ndarray
    place: np.ndarray | None = None
    spread: np.ndarray | None = None


def no_colours(bits: int = TABLE_BITS, shape: bool = False) -> CellColours:
    """A table of ``2^bits`` slots holding no cell (with the sums of the points' places
    when ``shape``)."""
    size = 1 << bits
    place = spread = None
    if shape:
        place, spread = np.zeros((size, 3), np.float32), np.zeros((size, 3, 3), np.float32)
    return CellColours(np.full(size, -1, np.int64), np.zeros(size, np.float32),
                       np.zeros((size, 3), np.float32), np.zeros(size, np.float32),
                       place, spread)


def add(table: CellColours, keys: np.ndarray, rgb: np.ndarray, offsets=None
        ) -> tuple[CellColours, np.ndarray]:
    """``table`` with the colours ``rgb [n, 3]`` of points in cells ``keys [n]`` added (and
    their ``offsets [n, 3]`` from their cells' centres, when the table keeps places), and
    each point's slot ``[n]`` (-1 where a clash within the batch left its cell out)."""
    cell, slot, fresh, mine = saturation.claim(table.cell, keys)
    sums = [a.copy() for a in table[1:] if a is not None]
    for a in sums:
        a[fresh] = 0
    rows, at = np.unique(slot[mine], return_inverse=True)

    def summed(values):  # [n, ...] -> [rows, ...]: per cell sums of the kept points
        flat = np.asarray(values, np.float64)[mine].reshape(int(mine.sum()), -1)
        out = np.stack([np.bincount(at, flat[:, j], len(rows)) for j in range(flat.shape[1])], 1)
        return out.reshape((len(rows),) + np.shape(values)[1:])

    rgb = np.asarray(rgb, np.float64)
    sums[0][rows] += np.bincount(at, minlength=len(rows))
    sums[1][rows] += summed(rgb)
    sums[2][rows] += summed(np.sum(rgb**2, 1))
    if table.place is not None:
        offsets = np.asarray(offsets, np.float64)
        sums[3][rows] += summed(offsets)
        sums[4][rows] += summed(offsets[:, :, None] * offsets[:, None, :])
    out = CellColours(cell, *sums) if table.place is not None else \
        CellColours(cell, *sums, None, None)
    return out, np.where(mine, slot, -1)


def spatial_occam(n, dim: int, prior: PriorConfig) -> np.ndarray:
    """``[p]`` nats: the Occam factor of a child's spatial parameters and weight, fitted to
    ``n [p]`` points of ``dim``-D space (module docstring): ``(dim / 2) log(1 + n /
    kappa_0) + (dim (dim + 1) / 4) log(1 + n / nu_0) + (1 / 2) log(1 + n / alpha)``."""
    n = np.asarray(n, np.float64)
    return (0.5 * dim * np.log1p(n / prior.mean_strength)
            + 0.25 * dim * (dim + 1) * np.log1p(n / prior.cov_strength)
            + 0.5 * np.log1p(n / prior.alpha))


def surface_gain(n, place, spread, mean, cov) -> np.ndarray:
    """``[p]`` nats: the shape term ``G`` of a child of a cell (module docstring): how much
    better, at the precision the component that explains the cell's points now has
    across its surface, a plane of the child's own explains their places along the
    cell's normal than that component's conditional does. ``n [p]`` points;
    ``place [p, 3]``, ``spread [p, 3, 3]``: the sums of their offsets from a point of the
    cell and of their outer products; ``mean [p, 3]``, ``cov [p, 3, 3]``: the
    component's mean (in the same frame as the offsets) and expected covariance."""
    n = np.maximum(np.asarray(n, np.float64), 1e-12)
    place, spread = np.asarray(place, np.float64), np.asarray(spread, np.float64)
    mean, cov = np.asarray(mean, np.float64), np.asarray(cov, np.float64)
    centre = place / n[:, None]
    scatter = spread - n[:, None, None] * centre[:, :, None] * centre[:, None, :]  # S
    axes = np.linalg.eigh(scatter)[1]
    normal, basis = axes[:, :, 0], axes[:, :, 1:]  # u (the least spread), B (3 x 2)
    across = np.maximum(np.einsum("pi,pij,pj->p", normal, scatter, normal), 0.0)  # u'Su
    off = centre - mean
    moment = scatter + n[:, None, None] * off[:, :, None] * off[:, None, :]  # M
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        precision = np.linalg.inv(cov)
        full = np.einsum("pij,pji->p", precision, moment)
        plane = np.einsum("pia,pij,pjb->pab", basis, cov, basis)  # the in-plane marginal
        inplane = np.einsum("pab,pba->p", np.linalg.inv(plane),
                            np.einsum("pia,pij,pjb->pab", basis, moment, basis))
        along = np.einsum("pi,pij,pj->p", normal, precision, normal)  # 1 / v
        gain = 0.5 * (full - inplane - across * along)
    return np.where(np.isfinite(gain), gain, -np.inf)  # a degenerate component: no split


def log_bayes_factor(n, total, square, m, *, colour_noise: float, strength: float
                     ) -> np.ndarray:
    """``[p]`` the colour log Bayes factor ``L`` of a child of a cell (module docstring)
    from the cell's ``n [p]`` points, their colour sum ``total [p, d]`` and sum of
    ``|c|^2`` ``square [p]``, against the colour mean ``m [p, d]`` of the component that
    explains them now; ``colour_noise`` is ``sigma_c``, ``strength`` is ``lambda_0``."""
    n = np.maximum(np.asarray(n, np.float64), 1e-12)
    total, m = np.asarray(total, np.float64), np.asarray(m, np.float64)
    d = total.shape[-1]
    mean = total / n[:, None]
    within = np.maximum(np.asarray(square, np.float64) - np.sum(total * mean, 1), 0.0)  # R_1
    miss = n * np.sum((mean - m) ** 2, 1)  # n |c_bar - m|^2 = R_0 - R_1
    a0 = 0.5 * strength * d
    b0 = a0 * colour_noise**2
    h0 = b0 + 0.5 * (within + miss)
    h1 = b0 + 0.5 * within + 0.5 * miss * strength / (n + strength)
    return (a0 + 0.5 * n * d) * np.log(h0 / h1) - 0.5 * d * np.log1p(n / strength)


def explaining(posterior, active: np.ndarray, x: np.ndarray, candidates: int = 1
               ) -> np.ndarray:
    """``[n]`` the slot of the component that explains each point ``x [n, d]`` (about the
    origin) now: of the ``candidates`` active components whose means are nearest, the
    one under whose expected Gaussian (weight ``alpha``, mean, expected covariance) the
    point is most probable; with one candidate, the nearest."""
    from scipy.spatial import cKDTree  # imported when used: 0.2-0.4 s at start-up

    slots = np.flatnonzero(active)
    means = np.asarray(posterior.space.mean, np.float64)[slots]
    k = int(min(candidates, len(slots)))
    _, near = cKDTree(means).query(x, k=k, workers=-1)
    near = slots[near.reshape(len(x), k)]
    if k == 1:
        return near[:, 0]
    cov = np.asarray(expfam.niw_expected_covariance(posterior.space), np.float64)
    precision, logdet = np.linalg.inv(cov[near]), np.linalg.slogdet(cov[near])[1]
    d = x[:, None, :] - np.asarray(posterior.space.mean, np.float64)[near]
    score = (np.log(np.asarray(posterior.alpha, np.float64))[near] - 0.5 * logdet
             - 0.5 * np.einsum("nki,nkij,nkj->nk", d, precision, d))
    return near[np.arange(len(x)), np.argmax(score, 1)]


def earned_levels(rule: grow.Growth, posterior, active: np.ndarray, xyz, rgb,
                  table: CellColours, *, prior: PriorConfig, gain: float, footprint=None,
                  floor: float = grow.REFINE_FOOTPRINTS) -> tuple[np.ndarray, CellColours]:
    """``[n, rule.levels]`` bool: the refinement levels each point of the batch ``xyz [n,
    d]``, ``rgb [n, 3]`` may seed a child at (its cell there earns one: the module
    docstring; column 0, new ground, is False), and the table with the batch's colours
    added. ``posterior``: the mixture whose active components (``active [k]``) explain the
    points now; ``footprint [n]``: the points' pixel footprints
    (:func:`vbgs.mapping.measurement.point_footprints`; None: every level)."""
    origin = np.asarray(posterior.origin, np.float64)
    x = np.asarray(xyz, np.float64) - origin
    n = len(x)
    earns = np.zeros((n, rule.levels), bool)
    allowed = np.full(n, rule.levels - 1, np.int64)
    if footprint is not None:
        ratio = rule.cell / (floor * np.maximum(np.asarray(footprint, np.float64), 1e-30))
        allowed = np.minimum(allowed, np.floor(np.log2(ratio)).astype(np.int64))
    if n == 0 or allowed.max() < 1:
        return earns, table
    m = None  # the colours of the components nearest the points (none yet: no split)
    if np.any(active):
        shape = table.place is not None
        nearest = explaining(posterior, active, x, SHAPE_CANDIDATES if shape else 1)
        m = np.asarray(posterior.colour.mean, np.float64)[nearest]
    # every level's cells in one pass over the table (one copy of it per batch)
    here = [np.flatnonzero(allowed >= lv) for lv in range(1, int(allowed.max()) + 1)]
    rows = np.concatenate(here)  # the points, level after level
    level = np.concatenate([np.full(len(h), lv) for lv, h in enumerate(here, 1)])
    keys = saturation.cell_keys(rule, x[rows], np.zeros(x.shape[1]), -level)
    offsets = None
    if table.place is not None:  # from each cell's centre (small: float32 sums hold)
        side = rule.cell * np.exp2(-level)[:, None]
        offsets = x[rows] - (grow.cell_index(x[rows] / side, 1.0) + 0.5) * side
    table, slot = add(table, keys, np.asarray(rgb)[rows], offsets)
    if m is None:
        return earns, table
    ok = slot >= 0
    s, rows, level = slot[ok], rows[ok], level[ok]
    score = log_bayes_factor(table.count[s], table.total[s], table.square[s], m[rows],
                             colour_noise=prior.colour_noise, strength=prior.colour_strength)
    score = score - spatial_occam(table.count[s], x.shape[1], prior)
    if table.place is not None:
        k = nearest[rows]
        centre = (x[rows] - offsets[ok])  # each row's cell centre, about the origin
        cov = np.asarray(expfam.niw_expected_covariance(posterior.space), np.float64)[k]
        mean = np.asarray(posterior.space.mean, np.float64)[k] - centre
        score = score + surface_gain(table.count[s], table.place[s], table.spread[s], mean,
                                     cov)
    earns[rows[score > gain], level[score > gain]] = True
    return earns, table
