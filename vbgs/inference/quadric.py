"""A measured point's local surface: a quadric fitted to its neighbours in the batch.

The neighbours are a patch ``[m, k]`` of indices with a weight (0 or 1) each: a frame's
points come with their pixels, and their patches are read off the frame's pixel grid,
masked where a window holds no point or crosses a depth edge
(:mod:`vbgs.inference.pixel_patches`); bare points take the ``k`` nearest in a KD-tree
(:func:`neighbour_index`, all weights 1: the reference). One fit serves both; a masked
point counts for nothing, a patch of fewer than :data:`QUADRIC_MIN_POINTS` fits a plane
and one of fewer than :data:`PLANE_MIN_POINTS` leaves its point where it was measured.

A grown component's prior is the reference that, under prior assignment, places every
later point's latent surface point (:func:`vbgs.inference.candidates.candidate_latent`),
so a measured (noisy) point is not seeded where it was measured but on the surface its
neighbours show (:func:`vbgs.inference.grow.seeds_on_patches`). That surface is fitted
here as a height over the patch's tangent plane,

    h(a, b) = c0 + c1 a + c2 b + c3 a^2 + c4 a b + c5 b^2,

with ``(a, b, h)`` the neighbours' coordinates about the point in the frame of the
patch's principal axes (least squares on the heights). The normal at the point is the
quadric's, ``n0 - c1 t1 - c2 t2`` normalised, and the seed is where the point's ray
meets the quadric (to first order: ``t = c0 / (n . u)`` steps of its noise ``u`` along
the ray, ``n`` unnormalised).

Why a quadric and not the patch's plane (the first version: the plane through the
patch's centre, its normal that of the covariance less the noise ``u u^T``): a plane
through 48 points of a curved surface lies inside it, and the point slid onto it moves
off the surface by up to the clip (``SEED_SIGMAS``) at oblique views; the quadric
follows the curvature, and on a surface without noise leaves the point where it is
(``c0 = 0``). Object, 128 px / 20k / 60 frames, validation views (``python -m
experiments.studies.val_probe fit-scene --scene object --simulate-sensor exact --sensor kinect``):
exact depth learned as a Kinect's, plane 24.51 dB, plane without the slide 25.68,
quadric 26.23 (exact model: 26.58); Kinect depth (``--simulate-sensor kinect``): plane
24.50, quadric 24.47; room, Kinect depth: plane 22.13, quadric 22.23.

The patch's axes are those of its spread less its points' noise ``u u^T`` (as the plane
of before had them): without it, oblique rays tilt a noisy plane's normal toward
themselves, and a plane seen with noise gave components 1.7 times as thick (0.0108
against 0.0063 at a noise of 0.05, ``tests/vbgs/inference/test_measurement_noise.py``).
With it, the same validation views: Kinect depth 24.61 dB (24.47 without), exact depth
learned as a Kinect's 26.26 (26.23). At 32 px, where 48 points span some 60 cm of the
object, the quadric fits worse than the plane (``tests/experiments/test_write_scene.py``'s
tiny run: 18.8 dB against 20.3).
"""

from __future__ import annotations

import numpy as np

# Below this many neighbours the quadratic terms are left out (a plane: 3 coefficients).
QUADRIC_MIN_POINTS = 10
# Below this many the patch tells no plane: the point keeps its ray as normal, no step.
PLANE_MIN_POINTS = 3
# The ridge of the quadric's normal equations, a share of their trace (least_squares):
# far below any term a patch can tell, enough to keep a term it cannot tell at 0.
RIDGE = 1e-12


def neighbour_index(x: np.ndarray, chosen: np.ndarray, neighbours: int) -> np.ndarray:
    """``[m, k]``: the indices of the ``k = min(neighbours, n)`` nearest points of
    ``x [n, 3]`` to each point ``x[chosen]`` (itself among them)."""
    from scipy.spatial import cKDTree  # imported when used: 0.2-0.4 s at start-up

    k = min(neighbours, len(x))
    _, idx = cKDTree(np.asarray(x, np.float64)).query(x[chosen], k=k, workers=-1)
    return np.asarray(idx).reshape(len(chosen), k)


def patches(x: np.ndarray, chosen: np.ndarray, neighbours: int) -> np.ndarray:
    """``[m, k, 3]`` float64: the points of :func:`neighbour_index`."""
    return np.asarray(x, np.float64)[neighbour_index(x, chosen, neighbours)]


def patch_axes(patch: np.ndarray, noise: np.ndarray | None = None,
               weight: np.ndarray | None = None) -> np.ndarray:
    """``[m, 3, 3]``: the principal axes of each patch ``[m, k, 3]`` (columns, by
    ascending spread: column 0 is the normal of the patch's plane, up to sign); with its
    points' noise along their rays, ``noise [m, k, 3]``, of the spread less the noise's
    ``u u^T`` (oblique rays otherwise tilt a noisy plane's normal toward them).
    ``weight [m, k]`` (0 or 1; None: all 1): a point of weight 0 counts for nothing (a
    patch on the pixel grid, :mod:`vbgs.inference.pixel_patches`)."""
    return _axes(list(np.moveaxis(patch, -1, 0)),
                 None if noise is None else list(np.moveaxis(noise, -1, 0)), weight)


def _axes(cols: list, noise: list | None, weight: np.ndarray | None) -> np.ndarray:
    """:func:`patch_axes` of the patch's coordinates ``cols`` (``[m, k]`` each) and its
    noise's (or None), one product of two coordinates at a time: an einsum over
    ``[m, k, 3]`` took three times as long."""
    w = np.ones(cols[0].shape) if weight is None else np.asarray(weight, np.float64)
    total = w.sum(1)  # [m]; the point itself has weight 1
    centred = [c - (_dot(w, c) / total)[:, None] for c in cols]
    cov = np.empty((len(w), len(cols), len(cols)))
    for i in range(len(cols)):
        wc = w * centred[i]
        wn = None if noise is None else w * noise[i]
        for j in range(i, len(cols)):
            v = _dot(wc, centred[j]) - (0.0 if noise is None else _dot(wn, noise[j]))
            cov[:, i, j] = cov[:, j, i] = v / total
    return np.linalg.eigh(cov)[1]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``[m]``: each row's ``sum_k a b`` of ``a, b [m, k]`` (an einsum: no ``[m, k]``
    product is made; four times as fast as its sum)."""
    return np.einsum("mk,mk->m", a, b)


def _columns(a: np.ndarray) -> list:
    """``[n, d]`` -> ``d`` contiguous float64 columns ``[n]`` (gathered faster)."""
    a = np.asarray(a, np.float64)
    return [np.ascontiguousarray(a[:, i]) for i in range(a.shape[1])]


def quadric_patches(x: np.ndarray, chosen: np.ndarray, neighbours: int,
                    ray: np.ndarray | None = None, *, index: np.ndarray | None = None,
                    weight: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For each point ``x[chosen]`` of ``x [n, 3]``: the unnormalised normal ``[m, 3]``
    of the quadric fitted to its ``neighbours`` nearest points of ``x`` (itself among
    them; module docstring) and the quadric's height ``c0 [m]`` above the point along
    the patch's axis ``n0`` (the surface at the point's own tangent coordinates).

    ``index [m, k]`` and ``weight [m, k]`` (0 or 1): a patch given instead of the nearest
    points (the pixel grid's window, :func:`vbgs.inference.pixel_patches.window`); its
    points of weight 0 count for nothing. A patch of fewer than
    :data:`QUADRIC_MIN_POINTS` points fits a plane; of fewer than :data:`PLANE_MIN_POINTS`
    its normal is the point's ``ray`` and its height 0 (the seed stays where it was
    measured; without ``ray`` the normal is the patch's first axis, arbitrary)."""
    x = np.asarray(x, np.float64)
    idx = neighbour_index(x, chosen, neighbours) if index is None else index
    w = np.ones(idx.shape) if weight is None else np.asarray(weight, np.float64)
    seed = x[chosen]  # [m, 3]
    gap = [c[idx] - seed[:, i, None] for i, c in enumerate(_columns(x))]  # 3 x [m, k]
    axes = _axes(gap, None if ray is None else [c[idx] for c in _columns(ray)], w)
    # the patch in its axes' frame: h (along the normal n0), a, b
    h, a, b = (w * sum(gap[i] * axes[:, i, c, None] for i in range(3)) for c in range(3))
    count = w.sum(1)  # [m]
    scale = np.sqrt(np.maximum((_dot(a, a) + _dot(b, b))[:, None] / count[:, None], 1e-300))
    a, b = a / scale, b / scale  # unit spread: the normal equations stay conditioned
    terms = [w, a, b]
    curved = count >= QUADRIC_MIN_POINTS  # [m]; a patch of too few points: a plane
    if curved.any():
        q = curved[:, None]  # a plane's quadratic columns are 0: least_squares gives 0
        terms += [np.where(q, a * a, 0.0), np.where(q, a * b, 0.0), np.where(q, b * b, 0.0)]
    coef = _solve(terms, h)  # [m, p]
    normal = (axes[:, :, 0] - (coef[:, 1, None] * axes[:, :, 1]
                               + coef[:, 2, None] * axes[:, :, 2]) / scale)
    height = coef[:, 0]
    few = count < PLANE_MIN_POINTS
    if ray is not None and few.any():
        normal = np.where(few[:, None], np.asarray(ray, np.float64)[chosen], normal)
        height = np.where(few, 0.0, height)
    return normal, height


def least_squares(design: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``[m, p]``: for each patch the coefficients ``c`` that minimise ``|design c - h|^2``
    (``design [m, k, p]``, ``h [m, k]``; a masked point is a row of zeros in both, so it
    counts for nothing), by the normal equations with a ridge of
    :data:`RIDGE` of their trace: a term the patch cannot tell (no spread along an axis)
    gets 0, as the pseudo-inverse's minimum norm gives it. The design's columns have unit
    spread (:func:`quadric_patches`), so the equations are well conditioned; the batched
    SVD of the pseudo-inverse took ten times as long (0.16 s for 6600 patches of 48
    points) for coefficients equal to 2e-9 of their size."""
    return _solve([design[..., p] for p in range(design.shape[-1])], h)


def _solve(terms: list, h: np.ndarray) -> np.ndarray:
    """:func:`least_squares` of the design's columns ``terms`` (``[m, k]`` each), its
    normal equations summed one pair of columns at a time (a batched product of
    ``[m, p, k]`` and ``[m, k, p]``, with the stacking, took twice as long)."""
    p = len(terms)
    gram = np.empty((len(h), p, p))
    rhs = np.empty((len(h), p, 1))
    for i in range(p):
        rhs[:, i, 0] = _dot(terms[i], h)
        for j in range(i, p):
            gram[:, i, j] = gram[:, j, i] = _dot(terms[i], terms[j])
    ridge = RIDGE * np.trace(gram, axis1=1, axis2=2)[:, None, None] * np.eye(p)
    return np.linalg.solve(gram + ridge, rhs)[..., 0]


def ray_steps(normal: np.ndarray, height: np.ndarray, ray: np.ndarray) -> np.ndarray:
    """``[m]``: the steps ``t`` along each point's noise ``ray [m, 3]`` that put it on its
    quadric, to first order (``normal [m, 3]`` unnormalised and ``height [m]`` of
    :func:`quadric_patches`): ``t = c0 / (n . u)``; 0 where the ray runs in the surface."""
    along = np.einsum("mi,mi->m", normal, ray)
    ok = np.abs(along) > 1e-12 * np.linalg.norm(normal, axis=1)
    return np.where(ok, height / np.where(ok, along, 1.0), 0.0)
