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

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.model import bucket_size
from vbgs.inference.precision import cholesky_solve, eigh3

# Below this many neighbours the quadratic terms are left out (a plane: 3 coefficients).
QUADRIC_MIN_POINTS = 10
# Below this many the patch tells no plane: the point keeps its ray as normal, no step.
PLANE_MIN_POINTS = 3
# The ridge of the quadric's normal equations, a share of their trace (least_squares):
# far below any term a patch can tell (a unit-spread column holds about a share 1/6 of the
# trace), above float32's rounding of the equations, so a term the patch cannot tell
# stays at 0.
RIDGE = 1e-6
# The upper triangle's entries of a symmetric 3x3 matrix, in eigh3's order.
_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


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
    patch = np.asarray(patch, np.float64)
    gap = patch - patch[:, :1]  # about a point of each patch: float32 keeps its spread
    w = np.ones(gap.shape[:2]) if weight is None else weight
    return _padded_call(_axes_jit, len(gap), gap, noise, w)


def axes(gap: jax.Array, noise: jax.Array | None, w: jax.Array) -> jax.Array:
    """:func:`patch_axes` of patches given about a point each, ``gap [m, k, 3]``, and
    their noise ``[m, k, 3]`` (or None), weights ``w [m, k]``, traced: float32 suffices,
    the patch's spread being taken about its own points (a patch of a few centimetres
    keeps seven digits of its own size wherever it lies); the axes by elementwise Jacobi
    (:func:`vbgs.inference.precision.eigh3`, a sixth of the time of XLA's batched
    ``eigh`` on the CPU)."""
    total = jnp.maximum(w.sum(1), 1.0)  # [m]; a padded patch (no weight) stays finite
    c = [g - ((w * g).sum(1) / total)[:, None] for g in _coords(gap)]  # centred, [m, k]
    n = None if noise is None else _coords(noise)
    pair = {}
    for i in range(3):  # one reduction per pair: XLA makes a product of [m, k, 3, 3] slowly
        for j in range(i, 3):
            v = (w * c[i] * c[j]).sum(1)
            pair[i, j] = v if n is None else v - (w * n[i] * n[j]).sum(1)
    return eigh3(*(pair[i, j] / total for i, j in _UPPER))[1]


def fit(gap: jax.Array, noise: jax.Array | None, w: jax.Array, ray: jax.Array | None
        ) -> tuple[jax.Array, jax.Array]:
    """The quadric of each patch given about its point, traced (module docstring):
    ``gap [m, k, 3]`` the neighbours less the point, ``noise [m, k, 3]`` (or None) their
    noise along their rays, ``w [m, k]`` (0 or 1) their weights, ``ray [m, 3]`` (or None)
    the point's own noise. Returns the unnormalised normal ``[m, 3]`` and the height
    ``c0 [m]``; a patch of fewer than :data:`PLANE_MIN_POINTS` kept points returns the
    point's ``ray`` and 0 (without ``ray``: the patch's first axis and 0). Float32
    suffices: the coordinates are about the point and scaled to unit spread, and the
    ridge (:data:`RIDGE`) sits above float32's rounding of the normal equations."""
    ax = axes(gap, noise, w)  # [m, 3, 3]
    g = _coords(gap)
    h, a, b = (w * sum(g[i] * ax[:, i, c, None] for i in range(3)) for c in range(3))
    count = w.sum(1)  # [m]
    scale = jnp.sqrt(jnp.maximum(((a * a).sum(1) + (b * b).sum(1))
                                 / jnp.maximum(count, 1.0), 1e-30))[:, None]
    a, b = a / scale, b / scale  # unit spread: the normal equations stay conditioned
    curved = (count >= QUADRIC_MIN_POINTS)[:, None]  # too few points: a plane
    terms = [w, a, b] + [jnp.where(curved, t, 0.0) for t in (a * a, a * b, b * b)]
    coef = _solve(terms, h)  # [m, 6]; a plane's quadratic columns are 0: their terms 0
    normal = ax[:, :, 0] - (coef[:, 1, None] * ax[:, :, 1]
                            + coef[:, 2, None] * ax[:, :, 2]) / scale
    height = coef[:, 0]
    if ray is not None:
        few = (count < PLANE_MIN_POINTS)[:, None]
        normal, height = jnp.where(few, ray, normal), jnp.where(few[:, 0], 0.0, height)
    return normal, height


def quadric_patches(x: np.ndarray, chosen: np.ndarray, neighbours: int,
                    ray: np.ndarray | None = None, *, index: np.ndarray | None = None,
                    weight: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For each point ``x[chosen]`` of ``x [n, 3]``: the unnormalised normal ``[m, 3]``
    of the quadric fitted to its ``neighbours`` nearest points of ``x`` (itself among
    them; module docstring) and the quadric's height ``c0 [m]`` above the point along
    the patch's axis ``n0`` (the surface at the point's own tangent coordinates), by
    :func:`fit`.

    ``index [m, k]`` and ``weight [m, k]`` (0 or 1): a patch given instead of the nearest
    points; its points of weight 0 count for nothing. A patch of fewer than
    :data:`QUADRIC_MIN_POINTS` points fits a plane; of fewer than :data:`PLANE_MIN_POINTS`
    its normal is the point's ``ray`` and its height 0 (the seed stays where it was
    measured; without ``ray`` the normal is the patch's first axis, arbitrary)."""
    x = np.asarray(x, np.float64)
    idx = neighbour_index(x, chosen, neighbours) if index is None else index
    w = np.ones(idx.shape) if weight is None else weight
    gap = x[idx] - x[chosen][:, None]
    noise = None if ray is None else np.asarray(ray, np.float64)[idx]
    own = None if ray is None else np.asarray(ray, np.float64)[chosen]
    return _padded_call(_fit_jit, len(gap), gap, noise, w, own)


def least_squares(design: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``[m, p]``: for each patch the coefficients ``c`` that minimise ``|design c - h|^2``
    (``design [m, k, p]``, ``h [m, k]``; a masked point is a row of zeros in both, so it
    counts for nothing), by the normal equations with a ridge of :data:`RIDGE` of their
    trace: a term the patch cannot tell (no spread along an axis) gets 0, as the
    pseudo-inverse's minimum norm gives it. The design's columns have unit spread
    (:func:`fit`), so the equations are well conditioned and positive definite, solved
    by Cholesky elementwise (:func:`vbgs.inference.precision.cholesky_solve`); the
    batched SVD of the pseudo-inverse took ten times as long as a batched LU."""
    design, h = jnp.asarray(design, jnp.float32), jnp.asarray(h, jnp.float32)
    return np.asarray(_solve([design[..., p] for p in range(design.shape[-1])], h))


def _solve(terms: list, h: jax.Array) -> jax.Array:
    """:func:`least_squares` of the design's columns ``terms`` (``[m, k]`` each), its
    normal equations summed one pair of columns at a time (elementwise: no product is
    rounded to TF32 on a GPU) and solved elementwise."""
    p = len(terms)
    rhs = [(t * h).sum(1) for t in terms]  # p of [m]
    gram = {(i, j): (terms[i] * terms[j]).sum(1) for i in range(p) for j in range(i, p)}
    ridge = RIDGE * jnp.maximum(sum(gram[i, i] for i in range(p)), 1e-30)
    for i in range(p):
        gram[i, i] = gram[i, i] + ridge
    return jnp.stack(cholesky_solve(gram, rhs), 1)


def _coords(a: jax.Array) -> list:
    """``[m, k, 3]`` -> its three coordinates ``[m, k]``."""
    return [a[..., i] for i in range(a.shape[-1])]


_axes_jit = jax.jit(axes)
_fit_jit = jax.jit(fit)


def _padded_call(fn, m: int, *arrays):
    """``fn`` of ``arrays`` (``[m, ...]`` each, or None) as float32, their rows padded to
    :func:`vbgs.inference.model.bucket_size` (with weight 0: a padded patch is finite and
    dropped) so batches of nearby sizes share one compiled function; the results'
    first ``m`` rows as float64 arrays."""
    size = bucket_size(max(m, 1))

    def pad(a):
        if a is None:
            return None
        a = np.asarray(a, np.float32)
        return np.concatenate([a, np.zeros((size - m,) + a.shape[1:], np.float32)])

    out = fn(*(pad(a) for a in arrays))
    return (np.asarray(out, np.float64)[:m] if not isinstance(out, tuple)
            else tuple(np.asarray(o, np.float64)[:m] for o in out))


def ray_steps(normal, height, ray):
    """``[m]``: the steps ``t`` along each point's noise ``ray [m, 3]`` that put it on its
    quadric, to first order (``normal [m, 3]`` unnormalised and ``height [m]`` of
    :func:`fit`): ``t = c0 / (n . u)``; 0 where the ray runs in the surface (within
    float32's rounding of it). Traceable."""
    along = (normal * ray).sum(-1)
    ok = jnp.abs(along) > 1e-6 * jnp.sqrt((normal * normal).sum(-1) * (ray * ray).sum(-1))
    return jnp.where(ok, height / jnp.where(ok, along, 1.0), 0.0)
