"""Depth measurement models: what real sensors and depth networks do to true depth.

NumPy on the host, seeded and deterministic. Each model turns a true z-depth map
``[h, w]`` (0, NaN or inf = none) into the depth a sensor would report (float32,
0 = no depth), and gives the axial standard deviation it adds, ``sigma_z(z, camera)``:

* ``exact``: identity.
* ``kinect``: Kinect v1 structured light (:class:`~vbgs.sensors.active.Kinect`):
  ``sigma_z = 0.0012 + 0.0019 (z - 0.4)^2`` m (Nguyen, Izadi and Lovell 2012),
  disparity quantised to 1/8 px (depth step ``z^2 / (8 * 580 * 0.075)``), range
  0.4-4.5 m, holes at depth edges, grazing angles and 2 % at random.
* ``realsense``: D435-like active stereo (:class:`~vbgs.sensors.active.RealSense`):
  ``sigma_z = z^2 * 0.08 / (f_px * 0.05)`` m, range 0.2-10 m, the same holes.
* ``mono``: a monocular depth network after alignment (:class:`~vbgs.sensors.mono.Mono`):
  per-frame scale and shift drift, a smooth warp, edges bled, depth on every pixel.

``level`` multiplies the noise (standard deviations, drifts, warp, random holes):
0 keeps every depth a model returns exact (the physical holes, and mono's depth on
pixels without any, remain), 1 is the published model, 2 twice its noise. ``holes``
(a :class:`~vbgs.sensors.holes.HoleSpec`, ``parse_holes("random:0.05")``) sets an
active sensor's holes apart from the level: none, physical only, random at a rate.

    from vbgs.sensors import SENSORS, simulate
    measured = simulate("kinect", frame.depth, frame.camera, seed=[0, i])
    sigma = SENSORS["kinect"].sigma_z(measured, frame.camera)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vbgs.sensors.active import ActiveSensor, Kinect, RealSense
from vbgs.sensors.base import DepthSensor, check_depth, check_level
from vbgs.sensors.holes import SENSOR_HOLES, HoleSpec, parse_holes, refuse_holes
from vbgs.sensors.mono import Mono
from vbgs.sensors.noise import kinect_sigma_z, kinect_step, realsense_sigma_z


@dataclass(frozen=True)
class Exact:
    """The true depth, unchanged: ``sigma_z = 0``."""

    name: str = "exact"

    def sigma_z(self, z, camera=None, level: float = 1.0) -> np.ndarray:
        check_level(level)
        return np.zeros(np.shape(z))

    def simulate(self, depth, camera, rng: np.random.Generator | None = None,
                 level: float = 1.0, hole_spec: HoleSpec = HoleSpec()) -> np.ndarray:
        refuse_holes(self.name, hole_spec)
        check_level(level)
        check_depth(depth, camera)
        return np.array(depth, np.float32)

    def surface(self, depth, camera=None, level: float = 1.0) -> np.ndarray:
        """All of it: the depth as given (float32)."""
        return np.asarray(depth, np.float32)


SENSORS: dict[str, DepthSensor] = {m.name: m for m in (Exact(), Kinect(), RealSense(), Mono())}
SENSOR_NAMES: tuple[str, ...] = tuple(SENSORS)
# the sensors whose holes a HoleSpec sets (the others make none)
HOLED_SENSORS: tuple[str, ...] = tuple(n for n, m in SENSORS.items() if isinstance(m, ActiveSensor))
# the sensors whose noise is drawn independently at each pixel (the active ones; a depth
# network's error is smooth): averaging neighbours removes it (vbgs.mapping.denoise)
WHITE_NOISE_SENSORS: tuple[str, ...] = HOLED_SENSORS


def sensor(name: str) -> DepthSensor:
    """The model registered as ``name``, or ValueError naming the choices."""
    if name not in SENSORS:
        raise ValueError(f"unknown depth sensor {name!r}: use one of {', '.join(SENSOR_NAMES)}")
    return SENSORS[name]


def simulate(name: str, depth, camera, *, rng: np.random.Generator | None = None,
             seed=None, level: float = 1.0, holes: HoleSpec = HoleSpec()) -> np.ndarray:
    """The depth ``[h, w]`` float32 that sensor ``name`` reports for the true depth
    ``depth [h, w]`` seen by ``camera``. Give exactly one of ``rng`` (a NumPy
    Generator, advanced) or ``seed`` (anything ``np.random.default_rng`` takes, e.g.
    ``[task_seed, frame_index]``): the same seed gives the same depth. ``holes``
    replaces an active sensor's own holes (:func:`~vbgs.sensors.holes.parse_holes`);
    the noise drawn is the same whatever the holes."""
    model = sensor(name)
    if (rng is None) == (seed is None):
        raise ValueError("give exactly one of rng (a numpy Generator) or seed")
    if rng is None:
        rng = np.random.default_rng(seed)
    return model.simulate(depth, camera, rng, check_level(level), holes)


__all__ = ["HOLED_SENSORS", "SENSORS", "SENSOR_HOLES", "SENSOR_NAMES", "WHITE_NOISE_SENSORS",
           "DepthSensor", "Exact", "HoleSpec", "Kinect", "Mono", "RealSense", "check_level", "kinect_sigma_z",
           "kinect_step", "parse_holes", "realsense_sigma_z", "refuse_holes", "sensor",
           "simulate"]
