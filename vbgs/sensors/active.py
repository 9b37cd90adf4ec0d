"""Active depth sensors: a Kinect v1 (structured light) and a RealSense D435-like
active stereo camera. Each adds Gaussian axial noise (:mod:`vbgs.sensors.noise`) and
returns no depth (0) at its holes (:mod:`vbgs.sensors.holes`).

``level`` scales the noise standard deviation, the Kinect's disparity step and the
random dropout rate; the holes at depth edges, grazing angles and range limits are
physical and the same at every level (they are taken from the true depth). A
:class:`~vbgs.sensors.holes.HoleSpec` replaces the holes (none, physical only, random
at a rate of its own whatever the level): the noise drawn stays the same.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import vbgs.sensors.holes as holes
import vbgs.sensors.noise as noise
from vbgs.sensors.base import check_depth, check_level
from vbgs.sensors.holes import HoleSpec


@dataclass(frozen=True)
class ActiveSensor:
    """The holes every active sensor here shares (see :mod:`vbgs.sensors.holes`)."""

    near: float
    far: float
    edge_threshold: float = holes.EDGE_THRESHOLD
    grazing_degrees: float = holes.GRAZING_DEGREES
    hole_rate: float = holes.HOLE_RATE  # random dropouts at level 1

    def holes(self, depth: np.ndarray, camera, rng: np.random.Generator,
              level: float = 1.0, hole_spec: HoleSpec = HoleSpec()) -> np.ndarray:
        """Mask ``[h, w]`` of the pixels with true depth that this sensor leaves empty
        (its own holes, or those ``hole_spec`` names)."""
        found = (holes.physical_holes(depth, camera, self.near, self.far,
                                      self.edge_threshold, self.grazing_degrees)
                 if hole_spec.physical else np.zeros(np.shape(depth), bool))
        rate = hole_spec.dropout_rate(self.hole_rate, level)
        return (found | holes.random_dropouts(depth.shape, rate, rng)) & holes.valid(depth)

    def _measure(self, z: np.ndarray, camera, rng, level: float) -> np.ndarray:
        raise NotImplementedError

    def surface(self, depth, camera=None, level: float = 1.0) -> np.ndarray:
        """All of it: the depth as measured (float32); holes are 0 already."""
        return np.asarray(depth, np.float32)

    def simulate(self, depth, camera, rng: np.random.Generator, level: float = 1.0,
                 hole_spec: HoleSpec = HoleSpec()) -> np.ndarray:
        """Measured depth ``[h, w]`` float32: the true depth with this sensor's noise,
        0 at its holes (its own, or those ``hole_spec`` names) and wherever the true
        depth is missing."""
        level = check_level(level)
        depth = check_depth(depth, camera)
        ok = holes.valid(depth)
        z = np.where(ok, depth, 0.0)
        measured = self._measure(z, camera, rng, level)  # draws before the dropouts
        hole = self.holes(z, camera, rng, level, hole_spec)
        return np.where(ok & ~hole & (measured > 0), measured, 0.0).astype(np.float32)


@dataclass(frozen=True)
class Kinect(ActiveSensor):
    """Kinect v1, structured light (Nguyen, Izadi and Lovell 2012; Khoshelham and
    Elberink 2012).

    Axial noise ``sigma_z(z) = 0.0012 + 0.0019 (z - 0.4)^2`` m, range 0.4-4.5 m.
    Depth is quantised as disparity is: a Kinect v1 reports disparity in 1/8 px steps
    with ``f b`` about 580 px * 0.075 m, so the depth step is
    ``z^2 / (8 * 580 * 0.075)`` m. Nguyen et al. fitted sigma_z to the Kinect's
    quantised output, so the Gaussian part drawn here has variance
    ``sigma_z^2 - step^2 / 12`` and the rounding adds the rest (Sheppard's correction):
    the simulated depth's standard deviation about the truth is ``level * sigma_z``
    (the disparity step scales with ``level`` too; level 0 rounds nothing).
    """

    name: str = "kinect"
    near: float = noise.KINECT_RANGE[0]
    far: float = noise.KINECT_RANGE[1]

    def sigma_z(self, z, camera=None, level: float = 1.0) -> np.ndarray:
        """``level * (0.0012 + 0.0019 (z - 0.4)^2)`` m, quantisation included; the
        camera is not needed (the step is the Kinect's own)."""
        return check_level(level) * noise.kinect_sigma_z(z)

    def _measure(self, z, camera, rng, level):
        step = noise.kinect_step(z)
        gauss = np.sqrt(np.maximum(noise.kinect_sigma_z(z) ** 2 - step**2 / 12.0, 0.0))
        noisy = z + level * gauss * rng.standard_normal(z.shape)
        return noise.quantise_disparity(noisy, level)


@dataclass(frozen=True)
class RealSense(ActiveSensor):
    """Active stereo like an Intel RealSense D435 (Grunnet-Jepsen, Sweetser and
    Woodfill, Intel's D400 tuning white paper).

    Axial noise ``sigma_z = z^2 * subpixel / (f_px * baseline)`` with baseline
    0.05 m, subpixel 0.08 px and ``f_px`` the frame camera's focal length (``fx``);
    range 0.2-10 m. The noise is Gaussian, scaled by ``level``.
    """

    name: str = "realsense"
    near: float = noise.REALSENSE_RANGE[0]
    far: float = noise.REALSENSE_RANGE[1]
    baseline: float = noise.REALSENSE_BASELINE
    subpixel: float = noise.REALSENSE_SUBPIXEL

    def sigma_z(self, z, camera=None, level: float = 1.0) -> np.ndarray:
        """``level * z^2 * subpixel / (camera.fx * baseline)`` m."""
        if camera is None:
            raise ValueError("the realsense sigma_z needs the camera (its focal length fx)")
        return check_level(level) * noise.realsense_sigma_z(z, float(camera.fx), self.baseline,
                                                            self.subpixel)

    def _measure(self, z, camera, rng, level):
        sigma = self.sigma_z(z, camera, level)
        return z + sigma * rng.standard_normal(z.shape)
