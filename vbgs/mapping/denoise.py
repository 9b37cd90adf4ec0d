"""A frame's depth noise averaged over the surface it lies on, before the learner reads it.

An active sensor's axial noise is drawn afresh at every pixel (:mod:`vbgs.sensors.active`),
while the surface it measures is smooth over a few pixels. On a plane the inverse depth
is affine in the pixel coordinates, ``1/z = a + b du + c dv`` about a pixel, so each
pixel's depth is replaced by ``1/a`` of the least-squares plane fitted, in inverse depth,
to the pixels within ``radius`` (a square window) that lie on its surface. Which do is
decided twice: first those within ``K_SIGMA`` of the pixel's own reading (the difference
of two readings: ``sqrt 2`` sigma) plus :data:`SLOPE_FOOTPRINTS` pixel footprints per
pixel of distance (an inclined surface), then those within ``K_SIGMA`` sigma of that
first plane. A pixel with fewer than :data:`MIN_POINTS` such neighbours (itself included)
keeps its reading.

What is left of the noise is derived, not tuned: with ``S = sum phi phi^T`` over the
inliers (``phi = (1, du, dv)``) the fitted intercept's variance is the reading's times
the leverage ``h = (S^-1)_00`` (``1/N`` on a full window: 0.2 of the standard deviation
at radius 2), returned by :func:`smoothed` as ``factor = sqrt(h)``. The learner's
measurement model (:mod:`vbgs.mapping.measurement`) takes one share for the whole frame,
the median (:func:`noise_left`), not each reading's own: the fitted depths of
neighbouring pixels share readings, so their errors are correlated and a component's
points are worth less than independent ones, and where a reading's window is cut (an
edge, a hole) its larger share widened growth's look-ups and the hit band there
(validation, as below, radius 2: each reading's own share 25.13 dB, the frame's median
25.45). On a curved surface the plane leaves a bias of about
``(r p)^2 / (2 rho)`` (``p`` the footprint, ``rho`` the radius of curvature): 4 mm on the
object's sphere at 128 px, against 14-26 mm of noise.

Only for noise that is independent from pixel to pixel (the active sensors'); a depth
network's error is smooth (:mod:`vbgs.sensors.mono`) and a plane fit removes none of it.
A real structured-light sensor correlates neighbouring readings through its matching
window at its native resolution; frames kept at a fraction of it (each pixel several
native ones) are nearer the independent case.

Measured (object, 128 px / 20k / 60 frames, the Kinect's noise, its holes and 2 % random
holes, 8 validation views, ``python -m experiments.studies.val_probe --val-views 8 fit-scene
--scene object --simulate-sensor kinect --sensor kinect``; exact depth 26.43 dB): no
smoothing 24.60 dB; a radius of 2 with the noise left at the reading's 24.98, at half
of it 25.02, at 0.3 of it 25.24, at 0.2 of it 25.38; radius 3 (the reading's noise)
24.70; radius 1 at 0.33 of it 25.22 (one-off runs patching the learner; the radius
itself is chosen in ``results/tuning/denoise/``: radius 1, 25.22). Test views, fit-scene's
defaults (``results/sensors/``): object 24.44 dB (exact 26.00), room 21.84 (22.82), walk
13.94 (its far ground lies beyond the Kinect's range); without the averaging, at an
earlier code (one-off runs), 23.76, 21.83 and 14.01. The
RealSense at 128 px (``sigma_z`` grows as ``1 / f_px``), validation views
(``results/tuning/denoise/realsense/``): object 15.64 -> 19.16 dB, room 17.29 -> 19.49 at
radius 1; at radius 2 21.45 and 20.56, at 3 21.90 and 20.68 (``realsense/wide/``), a noise
of several footprints wanting the wider window: each sensor has its own
(:data:`SENSOR_RADII`). Cost, jitted (the window's offsets unrolled into one fused pass):
15 ms a frame at 640 x 480 at radius 1, 26 ms at radius 2, on a quiet 2-core CPU (the
NumPy version it replaced: 180 and 360 ms with the cores shared), against some 0.25 s for
the rest of a budgeted frame. End to end it saves time: ``python -m experiments.run
fit-scene --scene room --size 640x480 --frames 10 --components 100000 --simulate-sensor
kinect --sensor kinect`` learns 1.51 s a frame (19.86 dB) against 1.80 s (19.78 dB) with the
averaging patched out, twice each on a quiet machine. float32 is enough: the fit is the same at scene scales
1e-3 to 1e3 (tested).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.mapping.image_shifts import padded, shifted
from vbgs.render.camera import valid_depth

DENOISE_RADIUS = 1  # window half-side in pixels (3 x 3); 0: no smoothing. Chosen on validation
# views at both of the project's sizes (8 views each, `python -m experiments.run tune --scene
# object room --simulate-sensor kinect --sensor kinect --val-views 8 --grid
# growth.denoise_radius=...`, results/tuning/denoise/mean.md and its size64/; rule: the
# best mean validation PSNR over the object and the room at both sizes): at 128 px / 20k /
# 60 frames (re-made at the code in the table's first line) 1 and 2 tie, 23.66 and 23.65 dB;
# at 64 px / 5000 / 20 frames 1 is the best, 21.51 against 21.14 at 2. A window is
# some 4 cm a pixel at 64 px: 5 x 5 spans the object's curves. Without the holes 2 is the
# better at 128 px (the object 25.78 against 25.36 dB; results/tuning/denoise/noise_only/).
# The window each sensor's readings are averaged over, by its model's name (DENOISE_RADIUS
# for any other sensor whose noise is white): the RealSense's noise spans several
# footprints and wants the wider window. Chosen as the Kinect's is, on its own validation
# views (the same commands with `--simulate-sensor realsense --sensor realsense`): 3 is the
# best mean of the object and the room at both sizes, 21.29 dB against 21.00 at 2 and
# 20.96 at 4 at 128 px (results/tuning/denoise/realsense/wide/mean.md; 1 scores 19.32,
# results/tuning/denoise/realsense/mean.md), 18.36 against 18.13 at 4, 17.79 at 2 and 16.78
# at 1 at 64 px (results/tuning/denoise/realsense/size64/mean.md).
SENSOR_RADII = {"kinect": DENOISE_RADIUS, "realsense": 3}
K_SIGMA = 3.0  # a neighbour farther than this many standard deviations is another surface
SLOPE_FOOTPRINTS = 2.0  # first pass: a neighbour d px away may differ by d times this
#                         many footprints more (a surface inclined up to 63 degrees)
MIN_POINTS = 6  # fewer inliers than this (the pixel included): the reading is kept


def _plane_fit(inlier) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Per pixel, the least-squares plane ``a + b du + c dv`` through the neighbours'
    inverse depths: ``inlier`` holds per window offset ``(dy, dx, ok, w)``, ``w [h, w]``
    the neighbour's inverse depth and ``ok [h, w]`` bool where it lies on the pixel's
    surface. Returns ``coef`` (three ``[h, w]``), the leverage ``h = (S^-1)_00 [h, w]``
    (1 where the plane is undetermined) and the inlier count. ``S`` is 3 x 3 and
    symmetric: solved by its cofactors, elementwise."""
    s00 = s01 = s02 = s11 = s12 = s22 = b0 = b1 = b2 = 0.0
    for dy, dx, ok, w in inlier:
        m = ok.astype(jnp.float32)
        mw = m * w
        s00, s01, s02 = s00 + m, s01 + dx * m, s02 + dy * m
        s11, s12, s22 = s11 + dx * dx * m, s12 + dx * dy * m, s22 + dy * dy * m
        b0, b1, b2 = b0 + mw, b1 + dx * mw, b2 + dy * mw
    c00, c01, c02 = s11 * s22 - s12**2, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
    c11, c12, c22 = s00 * s22 - s02**2, s01 * s02 - s00 * s12, s00 * s11 - s01**2
    det = s00 * c00 + s01 * c01 + s02 * c02
    solvable = det > 1e-6
    d = jnp.where(solvable, det, 1.0)
    coef = tuple(jnp.where(solvable, c / d, 0.0) for c in (
        c00 * b0 + c01 * b1 + c02 * b2, c01 * b0 + c11 * b1 + c12 * b2,
        c02 * b0 + c12 * b1 + c22 * b2))
    return coef, jnp.where(solvable, c00 / d, 1.0), jnp.where(solvable, s00, 0.0)


@functools.partial(jax.jit, static_argnames="radius")
def _smoothed(z: jax.Array, sig: jax.Array, focal, radius: int):
    """:func:`smoothed` on float32 ``z`` (0: no reading) and ``sig [h, w]``, jitted: the
    window's offsets unrolled (``radius`` static), one fused pass over the pixels."""
    ok = z > 0
    inv = jnp.where(ok, 1.0 / jnp.where(ok, z, 1.0), 0.0)
    h, w = z.shape
    zp, ip = padded(z, radius), padded(inv, radius)  # 0 outside the image
    window = [(dy, dx, shifted(zp, radius, dy, dx, h, w), shifted(ip, radius, dy, dx, h, w))
              for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)]
    near = [(dy, dx, ok & (zn > 0) & (jnp.abs(zn - z) <= (
        K_SIGMA * math.sqrt(2.0) * sig + SLOPE_FOOTPRINTS * math.hypot(dy, dx) * z / focal)),
        wn) for dy, dx, zn, wn in window]
    (a, b, c), _, _ = _plane_fit(near)
    band = K_SIGMA * sig / jnp.maximum(z, 1e-12) ** 2  # sigma in inverse depth (dw = dz / z^2)
    on_plane = [(dy, dx, ok & (wn > 0) & (jnp.abs(wn - (a + b * dx + c * dy)) <= band), wn)
                for dy, dx, _, wn in window]
    (a, _, _), leverage, count = _plane_fit(on_plane)
    take = ok & (count >= MIN_POINTS) & (a > 0) & (leverage < 1.0)
    return (jnp.where(take, 1.0 / jnp.where(take, a, 1.0), z),
            jnp.where(take, jnp.sqrt(leverage), 1.0))


def sensor_radius(sensor_name: str, chosen: int | None = None) -> int:
    """The averaging window's half-side in pixels for a sensor: ``chosen`` where given
    (``growth.denoise_radius``), else the sensor's own (:data:`SENSOR_RADII`, by its
    model's name; :data:`DENOISE_RADIUS` for one not listed)."""
    return SENSOR_RADII.get(sensor_name, DENOISE_RADIUS) if chosen is None else chosen


def smoothed(depth: np.ndarray, sigma: np.ndarray, focal: float,
             radius: int = DENOISE_RADIUS) -> tuple[np.ndarray, np.ndarray]:
    """``(depth [h, w], factor [h, w])``: ``depth`` (0, NaN or inf: none) with each
    reading replaced by its surface's plane fit (module docstring) and the share
    ``sqrt(h)`` of its noise ``sigma [h, w]`` (standard deviations, scene units) left
    (1 where the reading is kept); ``focal`` in pixels (a footprint is ``z / focal``).
    Pixels without depth stay without; ``radius`` 0 returns the depth unchanged."""
    depth = np.asarray(depth)
    ok = valid_depth(depth)
    if radius <= 0 or not ok.any():
        return depth, np.ones(depth.shape, np.float32)
    z = np.where(ok, depth, 0.0).astype(np.float32)
    sig = np.where(ok, np.asarray(sigma, np.float32), 0.0).astype(np.float32)
    out, factor = _smoothed(z, sig, np.float32(focal), radius)
    return np.where(ok, np.asarray(out), depth).astype(depth.dtype), np.asarray(factor)


def noise_left(depth: np.ndarray, factor: np.ndarray) -> float:
    """The share of the sensor's noise the learner takes for a whole smoothed frame: the
    median of ``factor [h, w]`` (:func:`smoothed`) over the pixels of ``depth`` with a
    reading (1 where none has). One share per frame, not each reading's own (module
    docstring)."""
    ok = valid_depth(np.asarray(depth))
    return float(np.median(factor[ok])) if ok.any() else 1.0
