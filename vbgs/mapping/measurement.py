"""How a frame's depth was measured, as the learner uses it.

A depth sensor's error lies along the ray a pixel is seen on: a reading z with axial
standard deviation ``sigma_z(z)`` places the point at ``o + z d`` with ``d`` the ray
direction scaled to unit camera depth, so the point's noise is ``R = u u^T`` with
``u = sigma_z(z) d`` (a rank-1 covariance, mostly along the ray). The learner takes
the noise into its conjugate update (:func:`vbgs.inference.model.e_step_with`): the
responsibilities score each point under the component convolved with its noise, and the
M-step's covariance is that of each point's latent surface point along its ray, ``E[y |
x]`` and ``Cov[y | x]`` under the assigning (reference) component
(:func:`vbgs.inference.candidates.candidate_latent`), so the posterior describes the
surface, not the surface blurred by the sensor; the means keep the measured points (the
noise averages away). Both stay sums over points, so under prior assignment with a fixed
reference a stream still equals one batch.

Why the latent points and not a moment deconvolution (``sum x x^T - sum R_n``, the first
version): the deconvolution is unbiased, but a component of N points keeps a scatter
error of ``sigma^2 sqrt(2 / N)``; at 128 px / 20k components a component holds about 15
points and a Kinect's sigma is 2.6 cm at 4 m, so each kept ~1.6 cm of random thickness
and tilt on a width of 1.2 cm. Object, 128 px / 20k / 60 frames, Kinect noise without
holes, validation views (exact depth 26.58 dB): the exact map's covariances swapped for
the deconvolved ones fell to 22.80 dB (its means: 26.16, colours and opacities: no
change); learned on the exact map's components, the noisy data gave 22.53 dB
deconvolved and 26.02 with the latent points. A stream's grown components are that
reference: seeded on the quadric their patch fits (:func:`vbgs.inference.grow.seeds_on_patches`).

The latent points' mean in place of the measured one (the reference's surface, a
quadric fit of 48 points, against a component's ~15 noisy points), tried: Kinect noise
without holes 25.08 -> 25.25 dB on these views, with the holes 24.61 -> 24.73, but the
room's validation views 22.25 -> 22.18 and the test views object 23.76 -> 23.79, room
21.83 -> 21.71; a blend counting the reference as 11 points (its measured error, 6.4 mm
rms against 21 mm of noise): object 24.71 / 23.77 (validation / test), room 22.22 / 21.76.
Not kept: no gain beyond a few hundredths on the object, and the room loses.

Where the rest of the noise's cost lies (same views, Kinect noise without holes, with
the latent means above: 25.25 dB against 26.58 exact). Oracle swaps learned two maps in
lockstep under one reference, one from the exact points, one from the noisy points with
their rays, each grown and merged as chosen: the learner costs little (the exact points under the
noisy run's reference: 25.41; the noisy map with the exact map's means, colours or
opacities: 25.19, 25.22, 25.16); the reference costs the rest. Growth on the exact
points (no noise, seeds at the points themselves): 26.19; seeds at the exact points
with the noisy normals: 25.88; the noisy selection (cells looked up two sigma along the
rays) with exact seeds and normals: 25.96. The quadric's seeds are some 6 mm (rms, 3 mm
median) off the surface along its normal at 2 cm of noise, and a robust (Cauchy) fit,
96 neighbours or a thicker prior (0.2, 0.4: 24.67, 24.38 dB with the holes, against
24.73) do not do better. Of the reference's cost about 0.5 dB is in the merges that
free slots once the 20k are spent (some 15k merges over the stream): chosen on the
exact map's posteriors, the noisy map reaches 25.77; chosen on its own, 25.25; on its
own covariances with the exact means, 25.20, or the reverse, 25.32; adding a share of
each component's noise to its covariance in the merge cost (0.1, 1: 24.69, 24.64 dB
with the holes) does not help either. With the measured means (this code) the same
picture: growth on the exact points 25.83 dB, merges chosen on the exact map 25.44,
on its own 25.08 (the run as it is).

Tried after that (object, 128 px / 20k / 60 frames, the Kinect's own noise and
holes, 4 validation views, ``python -m experiments.studies.val_probe fit-scene --scene object
--simulate-sensor kinect --sensor kinect``: 24.61 dB, exact depth 26.58; room 22.25; a
one-off script patching the mapper, not committed), none kept:

- the reference refined by later frames: each frame fits the quadric of its 48 points
  nearest an existing component's reference mean and moves the mean onto it and turns
  the prior's normal toward it, a running mean over up to 8 frames (an estimate kept only
  within 3 sigma and 45 degrees): 24.45 dB; the mean alone 24.52, the normal alone 24.64;
  within 1.5 sigma over up to 30 frames 24.51. The reference set to the posterior
  (measured) mean each time a component's count doubles from 8: 24.16;
- growth's noise: the Kinect grows 38k components (31k on new ground) where exact depth
  grows 21k (11k; the Kinect's holes without its noise 22.5k), because the lookups two
  sigma before and behind a point skip the cells between them (2 sigma is 4-5 cm, a
  component some 1.2 cm across). Looking up every
  half cell along the ray grows 23.7k (13.2k new ground) and scores 24.33 dB; at one
  sigma 24.23 (33.6k). Fewer merges do not help: the merges average the noise of the
  measured means (20k is also better than 14k or 30k components: 24.52, 24.02);
- merges chosen on the reference means in place of the posterior ones: 24.67 dB, the
  room 22.24; the posterior means' difference along the pair's normal shrunk by its noise
  (the measured less the latent scatter over N, per component): 24.57;
- the latent mean with the refined reference above (the mean along the normal from the
  reference's surface, averaged over frames; needs vbgs.inference.expfam): object
  24.98 dB (latent mean alone 24.73), but the room 22.07 (alone 22.18, against 22.25);
- the same within this package: the refined reference moved in-plane onto the posterior
  mean and its mean strength ``kappa_0`` raised to what its fits are worth in points
  (the precision of the running, inverse-variance weighted quadric heights times a
  point's noise variance along the normal; fits with a residual chi^2 over 2 left out):
  object 24.96 dB, room 22.07; ``kappa_0 = 11`` per frame fitted 24.89 / 21.99, capped
  at 10 points 24.82 / 22.15, chi^2 under 1.2 (room) 22.05; moved in-plane without the
  strength (room) 22.24. The pull toward the fitted surface is worth 0.2-0.35 dB on the
  object and costs the room as much: not a default.

The sensors and their ``sigma_z`` are :mod:`vbgs.sensors`; a map's sensor is
``Config.sensor`` (``exact``: nothing to take into account, no extra work).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.render.camera import (Camera, block_rays, check_frame, pixel_blocks, pixel_rows,
                                ray_slopes, turned_into, valid_depth)
from vbgs.sensors import sensor


def point_rays(camera: Camera, depth: np.ndarray, model: str, level: float = 1.0
               ) -> np.ndarray:
    """``u [n, 3]``: each valid depth pixel's noise along its ray, in world units, in
    the order :func:`vbgs.render.camera.unproject` returns the points
    (``R_n = u_n u_n^T``; module docstring)."""
    depth = np.asarray(depth)
    return _rays(camera, depth, np.flatnonzero(valid_depth(depth)), model, level)


def point_footprints(camera: Camera, depth: np.ndarray) -> np.ndarray:
    """``[n]``: the side of the patch of surface each valid depth pixel sees, head-on, in
    world units (``z / f``, ``f`` the mean focal length in pixels), in the order
    :func:`vbgs.render.camera.unproject` returns the points: how finely the frame
    resolves the ground there (:mod:`vbgs.inference.grow`: far ground gets coarse cells)."""
    depth = np.asarray(depth)
    return depth[valid_depth(depth)].astype(np.float64) / _focal(camera)


class FramePoints(NamedTuple):
    """A depth frame's valid pixels as a learner takes them (:func:`frame_points`)."""

    xyz: np.ndarray  # [n, 3] float32 world points (vbgs.render.camera.unproject)
    rgb: np.ndarray  # [n, 3] float32 their colours
    ray: np.ndarray | None  # [n, 3] float32 their noise along the rays (point_rays)
    footprint: np.ndarray | None  # [n] float64 their pixel footprints (point_footprints)
    pixel: np.ndarray  # [n] int their pixels, row * width + col (raster order)


def frame_points(camera: Camera, rgb: np.ndarray, depth: np.ndarray, model: str | None = None,
                 level: float = 1.0, footprints: bool = True) -> FramePoints:
    """The pixels of ``depth [h, w]`` with valid depth as :class:`FramePoints`: what
    :func:`vbgs.render.camera.unproject` (of ``rgb [h, w, 3]``), :func:`point_rays`
    (sensor ``model`` at ``level``; None: no rays) and :func:`point_footprints` (if
    ``footprints``) return, equal to the bit, from one pass over the pixels (their mask
    and indices found once; 10 ms a 640 x 480 frame against 72 ms for the
    functions one by one as they were, the float64 work a block of pixels at a time)."""
    rgb, depth = check_frame(camera, rgb, depth)
    pixel = np.flatnonzero(valid_depth(depth))
    n, flat, slopes = len(pixel), depth.reshape(-1), ray_slopes(camera)
    pose, width, focal = np.asarray(camera.pose), int(camera.width), _focal(camera)
    noise = None if model is None else sensor(model)
    xyz = np.empty((n, 3), np.float32)
    ray = None if noise is None else np.empty((n, 3), np.float32)
    footprint = np.empty(n, np.float64) if footprints else None
    for s in pixel_blocks(n):  # camera._world_points, _rays and point_footprints in one pass
        z, x, y = block_rays(flat, pixel[s], width, slopes)
        turned_into(xyz[s], pose, x * z, y * z, z)
        if noise is not None:
            _noise_into(ray[s], noise, camera, level, pose, z, x, y)
        if footprint is not None:
            footprint[s] = z / focal
    return FramePoints(xyz, pixel_rows(rgb, pixel).astype(np.float32, copy=False), ray,
                       footprint, pixel)


def _rays(camera: Camera, depth: np.ndarray, pixel: np.ndarray, model: str, level: float
          ) -> np.ndarray:
    """:func:`point_rays` at the pixels ``pixel [n]`` (``row * width + col``) of ``depth
    [h, w]``: ``sigma_z`` times the camera-frame ray, turned into the world in float64 a
    block of pixels and a column at a time (:func:`vbgs.render.camera._world_points`;
    NumPy's ``[n, 3] @ [3, 3]`` takes ten times as long), rounded to float32."""
    noise, flat, slopes = sensor(model), depth.reshape(-1), ray_slopes(camera)
    pose, width = np.asarray(camera.pose), int(camera.width)
    out = np.empty((len(pixel), 3), np.float32)
    for s in pixel_blocks(len(pixel)):
        _noise_into(out[s], noise, camera, level, pose, *block_rays(flat, pixel[s], width,
                                                                    slopes))
    return out


def _noise_into(out: np.ndarray, noise, camera: Camera, level: float, pose: np.ndarray,
                z: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    """Write into ``out [k, 3]`` the noise along the rays ``(x, y, 1)`` of readings at
    depth ``z`` (``[k]`` float64 each, :func:`vbgs.render.camera.block_rays`): the sensor
    ``noise``'s ``sigma_z`` times the ray, turned into the world by ``pose``."""
    sigma = np.asarray(noise.sigma_z(z, camera, level), np.float64)  # [k]
    turned_into(out, pose, x * sigma, y * sigma, sigma, moved=False)


def _focal(camera: Camera) -> float:
    """The mean focal length in pixels: a pixel's footprint is ``z`` over it."""
    return 0.5 * (float(camera.fx) + float(camera.fy))


def depth_variance(means, camera: Camera, model: str, level: float = 1.0) -> np.ndarray:
    """``[k]``: the sensor's variance of a depth reading at the camera depth of each
    world point ``means [k, 3]`` (0 behind the camera)."""
    pose = np.asarray(camera.pose, np.float64)
    z = (np.asarray(means, np.float64) - pose[:3, 3]) @ pose[:3, 2]  # camera z
    sigma = np.asarray(sensor(model).sigma_z(np.maximum(z, 0.0), camera, level), np.float64)
    return np.where(z > 0, sigma**2, 0.0).astype(np.float32)


def depth_sigmas(depth: np.ndarray, camera: Camera, model: str, level: float = 1.0
                 ) -> np.ndarray:
    """``[h, w]`` float64: the sensor's ``sigma_z`` of each depth reading, 0 where the
    pixel has no depth."""
    depth = np.asarray(depth)
    mask = valid_depth(depth)
    out = np.zeros(depth.shape, np.float64)
    if mask.any():
        out[mask] = sensor(model).sigma_z(depth[mask].astype(np.float64), camera, level)
    return out


def depth_weights(depth: np.ndarray, camera: Camera, model: str, level: float = 1.0
                  ) -> np.ndarray:
    """``[h, w]`` weights of a depth L1 term (the gradient baseline's,
    :mod:`vbgs.baseline.loss`): ``s_ref / sigma_z(d)`` at pixels with depth, ``s_ref``
    the median of ``sigma_z`` over them (so the weights average about 1 and the term
    keeps its scale); 1 elsewhere (those pixels take no part anyway)."""
    mask = valid_depth(np.asarray(depth))
    out = np.ones(mask.shape, np.float32)
    if not mask.any():
        return out
    sigma = depth_sigmas(depth, camera, model, level)[mask]
    if not (sigma > 0).all():
        return out  # an exact sensor (or level 0): every reading counts the same
    out[mask] = np.median(sigma) / sigma
    return out
