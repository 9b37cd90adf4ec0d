"""What every depth measurement model offers, and the checks of its inputs."""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from vbgs.sensors.holes import HoleSpec


class DepthSensor(Protocol):
    """A named depth measurement model.

    ``simulate(depth, camera, rng, level, hole_spec)`` returns the measured depth ``[h, w]``
    float32 (0 = no depth) of a true z-depth map ``[h, w]`` (0, NaN or inf = none)
    seen by ``camera`` (anything with ``fx, fy, cx, cy``, e.g.
    :class:`vbgs.render.camera.Camera`); ``sigma_z(z, camera, level)`` is the axial
    standard deviation, in scene units, that it adds to a surface at depth ``z``.
    ``level`` multiplies the noise: 0 keeps every depth it returns exact, 1 is the
    published model, 2 twice its noise. ``hole_spec`` (:mod:`vbgs.sensors.holes`) sets
    the holes an active sensor makes; a sensor that makes none refuses any but its own.
    """

    name: str

    def sigma_z(self, z, camera=None, level: float = 1.0) -> np.ndarray: ...

    def surface(self, depth: np.ndarray, camera, level: float = 1.0) -> np.ndarray:
        """The part of a depth map ``[h, w]`` this sensor measured that is surface,
        float32, the rest 0 (no depth): what a learner should take as surface. An active
        sensor's depth is all surface (its holes are 0 already); a depth network's
        far field and the depth it bled across edges are not."""
        ...

    def simulate(self, depth: np.ndarray, camera, rng: np.random.Generator,
                 level: float = 1.0, hole_spec: HoleSpec = HoleSpec()) -> np.ndarray: ...


def check_level(level) -> float:
    """The noise level as a float, or ValueError: a real number, finite, at least 0."""
    if isinstance(level, bool) or not isinstance(level, (int, float, np.integer, np.floating)):
        raise ValueError(f"sensor level must be a number >= 0, got {level!r}")
    if not (math.isfinite(level) and level >= 0):
        raise ValueError(f"sensor level must be a finite number >= 0 (0: exact depth, 1: the "
                         f"published model, 2: twice its noise), got {level!r}")
    return float(level)


def check_depth(depth, camera) -> np.ndarray:
    """The depth map as float64 ``[h, w]``, or ValueError if it does not match the camera."""
    depth = np.asarray(depth)
    shape = (int(camera.height), int(camera.width))
    if depth.shape != shape:
        raise ValueError(f"depth has shape {depth.shape}, expected {shape} (height, width) "
                         f"to match the camera")
    return depth.astype(np.float64)
