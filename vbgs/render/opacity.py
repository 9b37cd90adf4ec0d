"""Opacity from evidence: per component, the rays that end on it against the rays that
pass through it.

A splat's opacity is the probability that a ray through its footprint stops there.
Each frame is evidence about that, read off its depth map at a few pixels of the
component's projected footprint (the centre and one standard deviation either side
along u and v, ``N_SAMPLES`` = 5). With z the component's camera depth and
``σ_z = sqrt(r_zᵀ Σ r_z)`` its standard deviation along the camera's z axis ``r_z``,
a sample pixel whose observed depth D

* is within ``PASS_SIGMAS`` σ_z of z: the ray **hit** the component;
* is farther than ``z + PASS_SIGMAS σ_z``, or missing where the pixel shows nothing
  (sky, empty space; with exact depth every missing pixel does): the ray **passed
  through** it; a pixel missing elsewhere (a sensor's hole) is no evidence;
* is nearer than ``z - PASS_SIGMAS σ_z``: the component was occluded, no evidence.

Each sample stands for ``A / N_SAMPLES`` rays, ``A = 2π sqrt(det Σ')`` being the
footprint's area in pixels (Σ' the projected covariance), so a component's hits ``h``
and passes ``m`` are counts of rays, in the same units whatever its size. They are
the sufficient statistics of a Beta posterior, additive over frames:

    o ~ Beta(PRIOR_HITS + h, PRIOR_PASSES + m),   E[o] = (PRIOR_HITS + h) / (PRIOR_HITS + PRIOR_PASSES + h + m).

Read against a fixed reference model (the prior, under prior assignment) the counts
do not depend on the order of the frames, so the stream stays order-invariant; read
against the current posterior they follow it, like posterior assignment does.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.precision import ldl3, unit_lower_solve3
from vbgs.render.background import empty_pixels
from vbgs.render.camera import Camera
from vbgs.render.pixels import PIXEL_CENTRE_OFFSET
from vbgs.render.raster import BLUR_VARIANCE, NEAR, project
from vbgs.render.splats import Splats

# A surface within 4 sigma (camera z) of the component is a hit. Chosen on validation
# views: results/tuning/pass (python -m experiments.run tune --scene object room walk
# --grid evidence.pass_sigmas=1,2,3,4,6 --out results/tuning/pass): the best mean over
# the three scenes (results/tuning/pass/mean.md, re-made at the code in its first line):
# 4 the best, 3 to 6 within a few hundredths of a dB of each other.
PASS_SIGMAS = 4.0
N_SAMPLES = 5  # footprint pixels read per component and frame: centre, +-1 sigma in u and v
# Beta(1, 1): a uniform prior on opacity. A prior leaning to opaque (a component born
# from a depth return is a surface) changes little on validation views
# (results/tuning/evidence_prior/, `tune --scene object room walk --components K --grid
# evidence.prior_hits=1,2,4`): 4 is best there by a few hundredths of a dB of mean PSNR
# (rule: the best mean validation PSNR over the three scenes;
# results/tuning/evidence_prior/k20000_mean.md, k50000_mean.md, each with its code version
# in its first line); kept at 1, as every result would be re-made for a few hundredths.
PRIOR_HITS = 1.0
PRIOR_PASSES = 1.0
# A component is seen through in a frame when its samples, taken at least this many
# pixels from its centre, all passed: a footprint under a pixel would otherwise be one
# pixel's word, and a pixel's grid puts a thin edge's or a silhouette's own components
# beside the surface they were seeded on (vbgs.mapping.change).
THROUGH_PIXELS = 1.5


class Evidence(NamedTuple):
    """Rays that hit / passed through each component, summed over frames."""

    hits: jax.Array  # [k]
    passes: jax.Array  # [k]


def no_evidence(k: int) -> Evidence:
    """Before any frame: zero counts for ``k`` components."""
    return Evidence(jnp.zeros(k, jnp.float32), jnp.zeros(k, jnp.float32))


def expected_opacity(evidence: Evidence, prior_hits: float = PRIOR_HITS,
                     prior_passes: float = PRIOR_PASSES) -> jax.Array:
    """``E[o]`` ``[k]`` under the Beta(prior_hits + h, prior_passes + m) posterior."""
    hits = prior_hits + evidence.hits
    return hits / (hits + prior_passes + evidence.passes)


class FrameEvidence(NamedTuple):
    """One frame's evidence about each component: the rays that hit it and passed it, and
    whether the frame saw through it."""

    hits: jax.Array  # [k] rays that hit it
    passes: jax.Array  # [k] rays that passed through it
    seen_through: jax.Array  # [k] bool: every sample ray, each at least THROUGH_PIXELS
    #                          from the centre, passed through it (vbgs.mapping.change;
    #                          beyond its Gaussian along the ray where ``shaped``)
    shown: jax.Array  # [k, 3] the mean colour of the frame at the sample rays that hit it
    n_shown: jax.Array  # [k] int: how many hit samples that mean is over (0: no colour read)
    spread: jax.Array  # [k] the hit samples' mean squared distance from that mean (summed
    #                    over the channels): how much the colour varies across them (read
    #                    on the component's own Gaussian, ``colour_on``; else 0)
    blamed: jax.Array  # [k] int: hit samples whose colour the map as a whole does not
    #                    explain and the component's own colour does not either (``blame``;
    #                    0 without it, vbgs.mapping.change)


def observe(evidence: Evidence, means, covs, camera: Camera, depth, *,
            pass_sigmas: float = PASS_SIGMAS, sensor_var=None, empty=None) -> Evidence:
    """``evidence`` with one frame's hits and passes added (:func:`frame_evidence`, whose
    arguments it takes)."""
    return added(evidence, frame_evidence(means, covs, camera, depth, pass_sigmas=pass_sigmas,
                                          sensor_var=sensor_var, empty=empty))


def added(evidence: Evidence, frame: FrameEvidence) -> Evidence:
    """``evidence`` with one frame's hits and passes added (the counts are additive)."""
    return Evidence(evidence.hits + frame.hits, evidence.passes + frame.passes)


def frame_evidence(means, covs, camera: Camera, depth, *, pass_sigmas: float = PASS_SIGMAS,
                   sensor_var=None, empty=None, through_empty=None, through_reach=np.inf,
                   rgb=None, shaped=None, colour_on: bool = False, blame=None
                   ) -> FrameEvidence:
    """One frame's evidence for components with world ``means [k, 3]`` and
    ``covs [k, 3, 3]`` seen by ``camera`` with observed z-depth ``depth [h, w]``
    (0, NaN or inf where missing); a hit is within ``pass_sigmas`` sigma (camera z).

    Measured depth: ``sensor_var [k]`` is the sensor's variance of a depth reading at
    each component's camera depth, added to the component's own along camera z (the
    hit band widens with the noise, so noise does not turn hits into passes);
    ``empty [h, w]`` bool marks the pixels known to show nothing (sky, background):
    a pixel without depth counts as a pass there only. Elsewhere it is a hole in the
    measurement, which proves nothing (it must not lower opacity). Without ``empty``
    every pixel without depth is empty (exact depth: nothing else is missing).
    ``through_empty [h, w]``: the pixels without depth the see-through test takes as
    free space (None: ``empty``; a sensor's missing pixels, out of its range, say
    nothing about what stands there), and that only for a component whose hit band ends
    nearer than ``through_reach`` (camera depth): a sensor's range, within which a
    surface standing there would have returned a depth (inf: at any depth).
    ``rgb [h, w, 3]``: the frame's colours, of which
    the mean over each component's hit samples is returned (None: no colour read);
    ``colour_on``: over those of its hit samples alone whose surface point lies within
    its own Gaussian, ``pass_sigmas`` Mahalanobis sigmas of it (:func:`_along_ray`; a
    sample on a neighbouring surface within the hit band tells nothing of its colour).
    ``shaped [k]`` bool: the components whose see-through is judged along each ray's
    own Gaussian (:func:`_far_along_ray`, :mod:`vbgs.mapping.change`), the others
    against the hit band (None: none). ``blame``: ``(unexplained [h, w] bool, tolerance
    [h, w], own [k, 3])``, the pixels whose colour the map as a whole fails to explain, the
    squared colour distance allowed at each and the components' own colours
    (:func:`vbgs.mapping.change.unexplained`): each component's hit samples on such a pixel
    whose colour lies farther than the tolerance from its own are counted (``blamed``;
    None: none, 0)."""
    k = np.shape(means)[0]
    sensor_var = np.zeros(k, np.float32) if sensor_var is None else sensor_var
    empty = empty_pixels(depth) if empty is None else empty
    through_empty = empty if through_empty is None else through_empty
    return FrameEvidence(*_frame_counts(
        bool(colour_on), jnp.float32(pass_sigmas), jnp.asarray(sensor_var, jnp.float32),
        jnp.asarray(empty), jnp.asarray(through_empty), jnp.float32(through_reach),
        None if rgb is None else jnp.asarray(rgb, jnp.float32),
        None if shaped is None else jnp.asarray(shaped, bool),
        None if blame is None else tuple(jnp.asarray(b) for b in blame),
        jnp.asarray(means, jnp.float32), jnp.asarray(covs, jnp.float32),
        *(jnp.asarray(v, jnp.float32) for v in (camera.fx, camera.fy, camera.cx, camera.cy)),
        jnp.asarray(camera.pose, jnp.float32), jnp.asarray(depth, jnp.float32),
    ))


def _far_along_ray(means, covs, sensor_var, pose, fx, fy, cx, cy, pass_sigmas, shaped,
                   far_side):
    """``far(uv [s, k, 2]) -> [s, k]``: the camera depth beyond which the ray through the
    centre of the pixel at ``uv`` (the ray its depth was read along) has passed each
    component: the Gaussian taken along the ray itself (:func:`_along_ray`; module
    docstring of :mod:`vbgs.mapping.change`), its mean depth ``t*`` there and
    ``pass_sigmas`` of its standard deviation beyond; ``far_side [k]`` (the hit band's)
    where not ``shaped``."""
    along = _along_ray(means, covs, sensor_var, pose, fx, fy, cx, cy)

    def far(uv):
        centre, variance, _ = along(uv)
        return jnp.where(shaped[None], centre + pass_sigmas * jnp.sqrt(variance),
                         far_side[None])

    return far


def _along_ray(means, covs, sensor_var, pose, fx, fy, cx, cy):
    """``along(uv [s, k, 2]) -> (t*, var, miss)``, each ``[s, k]``: each component's
    Gaussian taken along the ray through the centre of the pixel at ``uv`` (the ray its
    depth was read along), ``r`` that ray scaled to unit camera depth from the camera
    centre ``c``: its mean depth there ``t* = rᵀ Σ⁻¹ (μ - c) / rᵀ Σ⁻¹ r``, its variance
    ``1 / rᵀ Σ⁻¹ r + sensor_var`` (a reading's noise added), and ``miss``, the squared
    Mahalanobis distance from ``μ`` of the ray's point at ``t*`` (how far the ray passes
    from the component: a surface point read at depth ``D`` on that ray lies
    ``miss + (D - t*)² / var`` squared sigmas from it). The covariance is inverted
    through its LDLᵀ factors at unit trace, elementwise
    (:func:`vbgs.inference.precision.ldl3`: stable for a thin component in float32)."""
    scale = jnp.maximum(jnp.trace(covs, axis1=-2, axis2=-1), 1e-30)  # [k]
    f = ldl3(covs / scale[:, None, None] + 1e-6 * jnp.eye(3))
    weight = [1.0 / (d * scale) for d in (f.d0, f.d1, f.d2)]  # Σ⁻¹ = L⁻ᵀ diag(weight) L⁻¹
    offset = unit_lower_solve3(f, *(means - pose[:3, 3]).T)  # L⁻¹ (μ - c), entries [k]
    rot = pose[:3, :3]

    def along(uv):
        centre_uv = jnp.floor(uv) + PIXEL_CENTRE_OFFSET  # the read pixel's: its depth's ray
        u, v = (centre_uv[..., 0] - cx) / fx, (centre_uv[..., 1] - cy) / fy  # [s, k]
        ray = unit_lower_solve3(f, *(rot[i, 0] * u + rot[i, 1] * v + rot[i, 2]
                                     for i in range(3)))  # L⁻¹ r, r at unit camera depth
        curvature = jnp.maximum(sum(y * y * w for y, w in zip(ray, weight, strict=True)),
                                1e-30)  # rᵀ Σ⁻¹ r
        centre = sum(y * o * w for y, o, w in zip(ray, offset, weight, strict=True)) / curvature
        miss = sum((centre * y - o) ** 2 * w for y, o, w in zip(ray, offset, weight,
                                                                  strict=True))
        return centre, 1.0 / curvature + sensor_var[None], miss

    return along


def _over_samples(planes):
    """The sum of the per-sample planes ``[k, ...]``, adjacent pairs first (five samples:
    ``((0 + 1) + (2 + 3)) + 4``, the order XLA:CPU's reduction over a leading axis of five
    takes, so the sums keep their bits). Summed over the leading axis of ``[5, k, 3]`` the
    frame's colours took 7 ms at 100k components on a 2-core CPU, the planes' sum 2: a
    reduction over a short major axis with a trailing axis of three vectorises badly."""
    while len(planes) > 1:
        planes = [a + b for a, b in zip(planes[::2], planes[1::2], strict=False)] + (
            [planes[-1]] if len(planes) % 2 else [])
    return planes[0]


@partial(jax.jit, static_argnums=0)
def _frame_counts(colour_on, pass_sigmas, sensor_var, empty, through_empty, through_reach,
                  rgb, shaped, blame, means, covs, fx, fy, cx, cy, pose, depth):
    """Hits and passes ``[k]`` of one frame (module docstring), whether it was seen
    through ``[k]`` (the five samples taken at least ``THROUGH_PIXELS`` apart all passed)
    and the mean colour ``[k, 3]`` of ``rgb`` at the samples that hit, with their number
    ``[k]`` (0 where ``rgb`` is None: no colour read), and the hit samples ``blame`` puts
    on the component ``[k]`` (0 where it is None)."""
    height, width = depth.shape
    k = means.shape[0]
    splats = Splats(means, covs, jnp.zeros((k, 3)), jnp.ones(k))
    proj = project(splats, fx, fy, cx, cy, pose, NEAR, BLUR_VARIANCE, width=width,
                   height=height)
    a, b, c = proj.conic.T  # Σ'⁻¹ = [[a, b], [b, c]]
    det_conic = a * c - b * b
    ellipse = proj.visible  # no ellipse (an indefinite covariance): no evidence (raster.project)
    det_conic = jnp.where(ellipse, det_conic, 1.0)
    area = jnp.where(ellipse, 2.0 * jnp.pi / jnp.sqrt(det_conic), 0.0)  # [k] ∫ exp(-½ dᵀ Σ'⁻¹ d) dd
    sigma_u = jnp.sqrt(jnp.where(ellipse, c, 1.0) / det_conic)  # sqrt of Σ' diagonal
    sigma_v = jnp.sqrt(jnp.where(ellipse, a, 1.0) / det_conic)
    axis_z = pose[:3, 2]  # camera z axis in world coordinates
    sigma_z = jnp.sqrt(jnp.maximum(jnp.einsum("i,kij,j->k", axis_z, covs, axis_z), 0.0)
                       + sensor_var)
    near_side = proj.depth - pass_sigmas * sigma_z
    far_side = proj.depth + pass_sigmas * sigma_z

    def sample(du, dv, empty, far=None, reach=None):  # the centre and du, dv [k] px either
        zero = jnp.zeros(k)  # side: hit, passed (beyond ``far(uv)`` when given; an empty
        #                      pixel only for a band that ends nearer than ``reach``)
        offsets = jnp.stack([jnp.stack([zero, zero], -1), jnp.stack([du, zero], -1),
                             jnp.stack([-du, zero], -1), jnp.stack([zero, dv], -1),
                             jnp.stack([zero, -dv], -1)])  # [N_SAMPLES, k, 2]
        uv = proj.uv[None] + offsets
        col = jnp.floor(uv[..., 0]).astype(jnp.int32)
        row = jnp.floor(uv[..., 1]).astype(jnp.int32)
        inside = (col >= 0) & (col < width) & (row >= 0) & (row < height) & ellipse[None]
        row, col = jnp.clip(row, 0, height - 1), jnp.clip(col, 0, width - 1)
        observed = depth[row, col]  # [s, k]
        has_depth = jnp.isfinite(observed) & (observed > 0)
        shows_nothing = empty[row, col]
        hit = inside & has_depth & (observed >= near_side) & (observed <= far_side)
        beyond = far_side if far is None else far(uv)
        if reach is not None:  # inf: every component (the comparison left out)
            shows_nothing = shows_nothing & (jnp.isinf(reach) | (far_side < reach))[None]
        passed = inside & ((~has_depth & shows_nothing) | (has_depth & (observed > beyond)))
        return hit, passed, row, col, uv, observed

    hit, passed, row, col, uv, observed = sample(sigma_u, sigma_v, empty)
    per_sample = area / N_SAMPLES
    wide = jnp.float32(THROUGH_PIXELS)
    far = None if shaped is None else _far_along_ray(  # None: the band alone (no inverse)
        means, covs, sensor_var, pose, fx, fy, cx, cy, pass_sigmas, shaped, far_side)
    _, through, *_ = sample(jnp.maximum(sigma_u, wide), jnp.maximum(sigma_v, wide),
                              through_empty, far, through_reach)
    n_hit = hit.sum(0)
    if rgb is not None:  # the colours the hits show (on the component's own Gaussian)
        on = hit
        if colour_on:
            centre, variance, miss = _along_ray(means, covs, sensor_var, pose, fx, fy, cx,
                                                cy)(uv)
            on = hit & (miss + (observed - centre) ** 2 / variance <= pass_sigmas**2)
        n_on = on.sum(0)
        colours = rgb[row, col]  # [s, k, 3]
        weight = on.astype(colours.dtype)
        shown = _over_samples([c * o[:, None] for c, o in zip(colours, weight, strict=True)]) \
            / jnp.maximum(n_on, 1)[:, None]
        spread = ((((colours - shown[None]) ** 2).sum(-1) * on).sum(0) / jnp.maximum(n_on, 1)
                  if colour_on else jnp.zeros(k))  # the posterior reference's alone
        n_shown = n_on.astype(jnp.int32)
    else:
        shown, n_shown, spread = jnp.zeros((k, 3)), jnp.zeros(k, jnp.int32), jnp.zeros(k)
    if blame is not None:  # unexplained by the map, and by the component's own colour
        unexplained, tolerance, own = blame
        rgb_at = rgb[row, col]  # [s, k, 3]
        off = ((rgb_at - own[None]) ** 2).sum(-1) > tolerance[row, col]
        blamed = (hit & unexplained[row, col] & off).sum(0).astype(jnp.int32)
    else:
        blamed = jnp.zeros(k, jnp.int32)
    return (n_hit * per_sample, passed.sum(0) * per_sample, through.all(0), shown, n_shown,
            spread, blamed)
