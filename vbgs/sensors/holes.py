"""Where active depth sensors return no depth: boolean masks ``[h, w]`` (True = hole).

* Depth edges: a pixel whose 4-neighbour's depth differs by more than a threshold
  (5 cm by default, in scene units) along a jump steeper than the grazing limit (so
  an inclined smooth surface is no edge at any resolution, see :func:`depth_edges`);
  a neighbour without depth counts as infinitely far, so silhouettes against empty
  background are edges. Both sides of a jump are holes: a structured-light or stereo
  sensor cannot match the pattern there (the projector or the second camera sees the
  other surface, or nothing).
* Grazing angles: the angle between the pixel's ray and the surface normal, both
  from the depth map, above about 75 degrees: the pattern is smeared along the
  surface and matching fails.
* Range limits: depth outside ``[near, far]``.
* Random dropouts: each pixel independently with probability ``rate``.

The first three are physical: they depend on the true depth only, never on the noise
level or the seed. Pixels without depth in the input (0, NaN or inf) are not holes
here; they stay without depth.

Which of them a simulated sensor makes is a :class:`HoleSpec`, written as text by
:func:`parse_holes` (``sensor``: the sensor's own; ``none``; ``physical``;
``random:RATE``; ``physical+random:RATE``): a robustness study varies the holes apart
from the noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vbgs.render.pixels import pixel_rays

EDGE_THRESHOLD = 0.05  # scene units (5 cm): a larger jump between 4-neighbours is an edge
GRAZING_DEGREES = 75.0  # ray-to-normal angle beyond which a surface returns no depth
HOLE_RATE = 0.02  # random dropouts at level 1
SENSOR_HOLES = "sensor"  # the spec of a sensor's own holes (physical, level x its dropout rate)
HOLE_SPECS = (SENSOR_HOLES, "none", "physical", "random:RATE", "physical+random:RATE")


@dataclass(frozen=True)
class HoleSpec:
    """Which holes a simulated active sensor makes.

    physical: the holes of the true depth (edges, grazing angles, range limits);
    dropout: each pixel's probability of a random dropout, or None for the sensor's own
        (its ``hole_rate`` times the noise level).
    """

    physical: bool = True
    dropout: float | None = None

    def __post_init__(self):
        if self.dropout is not None and not (
                isinstance(self.dropout, (int, float)) and 0.0 <= self.dropout <= 1.0):
            raise ValueError(f"a random dropout rate is a probability in [0, 1], "
                             f"got {self.dropout!r}")

    @property
    def own(self) -> bool:
        """The sensor's own holes (nothing changed)."""
        return self.physical and self.dropout is None

    def dropout_rate(self, sensor_rate: float, level: float) -> float:
        """The dropout probability per pixel: the given one, or ``level * sensor_rate``."""
        return level * sensor_rate if self.dropout is None else float(self.dropout)


def parse_holes(spec: str) -> HoleSpec:
    """The :class:`HoleSpec` a text names: ``sensor`` (the sensor's own holes),
    ``none``, ``physical`` (edges, grazing angles, range limits), ``random:RATE`` (random
    dropouts only, RATE in [0, 1]: e.g. ``random:0.05``) or ``physical+random:RATE``;
    ValueError naming the forms otherwise."""
    forms = ", ".join(HOLE_SPECS)
    if not isinstance(spec, str):
        raise ValueError(f"holes must be text, one of {forms}; got {spec!r}")
    if spec == SENSOR_HOLES:
        return HoleSpec()
    if spec in ("none", "physical"):
        return HoleSpec(physical=spec == "physical", dropout=0.0)
    head, _, rate = spec.partition("random:")
    if head not in ("", "physical+") or not rate:
        raise ValueError(f"unknown holes {spec!r}: use one of {forms} (RATE a probability "
                         f"in [0, 1], e.g. random:0.05)")
    try:
        value = float(rate)
    except ValueError:
        value = math.nan
    if not 0.0 <= value <= 1.0:  # NaN fails too
        raise ValueError(f"holes {spec!r}: the random dropout RATE must be a probability in "
                         f"[0, 1], e.g. random:0.05; got {rate!r}")
    return HoleSpec(physical=head == "physical+", dropout=value)


def refuse_holes(sensor: str, spec: HoleSpec) -> None:
    """ValueError if ``spec`` asks a sensor that makes no holes (exact, mono) for some."""
    if not spec.own:
        raise ValueError(f"the {sensor} sensor makes no holes, so they cannot be set; hole "
                         f"settings apply to the active sensors (vbgs.sensors.HOLED_SENSORS)")


def valid(depth: np.ndarray) -> np.ndarray:
    """Pixels with depth: finite and strictly positive."""
    depth = np.asarray(depth)
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0)


def depth_edges(depth: np.ndarray, threshold: float = EDGE_THRESHOLD, camera=None,
                grazing_degrees: float = GRAZING_DEGREES) -> np.ndarray:
    """Pixels with depth whose up, down, left or right neighbour (inside the image)
    differs by more than ``threshold`` or has no depth.

    With a ``camera``, a jump counts only if it is also steeper than any surface the
    sensor sees: the segment joining the two pixels' 3-D points lies within
    ``90 - grazing_degrees`` degrees of the ray through its middle. A smooth surface
    inclined less than the grazing limit then never gives an edge, whatever the
    frame's resolution (at 64 px and 4 m a pixel spans about 4.5 cm, so a plain 5 cm
    test would cut most inclined surfaces); at a Kinect's native 580 px focal length a
    75 degree surface at 4 m changes by 2.6 cm per pixel, and the two tests agree.
    """
    ok = valid(depth)
    z = np.where(ok, np.asarray(depth, np.float64), np.inf)  # no depth: infinitely far
    points = None if camera is None else camera_points(np.where(ok, z, 0.0), camera)
    edge = np.zeros(z.shape, bool)
    for axis in (0, 1):
        a = [slice(None), slice(None)]
        b = [slice(None), slice(None)]
        a[axis], b[axis] = slice(1, None), slice(None, -1)
        a, b = tuple(a), tuple(b)
        with np.errstate(invalid="ignore"):
            jump = ~(np.abs(z[a] - z[b]) <= threshold)  # inf - inf is NaN: a jump
        if points is not None:
            jump &= ~(ok[a] & ok[b]) | _steep(points[a], points[b], grazing_degrees)
        edge[a] |= jump
        edge[b] |= jump
    return edge & ok


def _steep(p: np.ndarray, q: np.ndarray, grazing_degrees: float) -> np.ndarray:
    """Whether the segment ``p -> q`` (``[..., 3]`` each) lies within ``90 -
    grazing_degrees`` degrees of the ray through its middle."""
    step, mid = q - p, 0.5 * (p + q)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(np.sum(step * mid, -1)) / (np.linalg.norm(step, axis=-1)
                                                * np.linalg.norm(mid, axis=-1))
    return cos > np.cos(np.radians(90.0 - grazing_degrees))


def camera_points(depth: np.ndarray, camera) -> np.ndarray:
    """Camera-frame points ``[h, w, 3]`` (float64) of every pixel at its depth."""
    h, w = np.shape(depth)
    rays = pixel_rays(h, w, camera.fx, camera.fy, camera.cx, camera.cy)  # [h, w, 3], z = 1
    return rays * np.asarray(depth, np.float64)[..., None]


def _smooth_difference(points: np.ndarray, ok: np.ndarray, axis: int) -> np.ndarray:
    """Per pixel, the forward or backward difference of ``points`` along ``axis``
    (0: rows, 1: columns) whose depth changes least, among those with both ends
    valid; NaN where neither is (a one-sided difference keeps a normal off the far
    side of an edge)."""
    p = np.moveaxis(points, axis, 0)  # [n, m, 3]
    k = np.moveaxis(ok, axis, 0)  # [n, m]
    step = p[1:] - p[:-1]  # [n-1, m, 3]
    step_ok = k[1:] & k[:-1]
    nan = np.full((1,) + step.shape[1:], np.nan)
    fwd = np.concatenate([np.where(step_ok[..., None], step, np.nan), nan])  # [n, m, 3]
    bwd = np.concatenate([nan, np.where(step_ok[..., None], step, np.nan)])
    dz_f, dz_b = np.abs(fwd[..., 2]), np.abs(bwd[..., 2])
    use_bwd = np.isnan(dz_f) | (dz_b < dz_f)
    return np.moveaxis(np.where(use_bwd[..., None], bwd, fwd), 0, axis)


def ray_normal_angle(depth: np.ndarray, camera) -> np.ndarray:
    """Angle in degrees ``[h, w]`` between each pixel's ray and the surface normal
    estimated from the depth map (the cross product of its row and column tangents);
    NaN where no tangent is available (no depth, or no neighbour with depth)."""
    ok = valid(depth)
    points = camera_points(np.where(ok, depth, 0.0), camera)  # [h, w, 3]
    normal = np.cross(_smooth_difference(points, ok, 1), _smooth_difference(points, ok, 0))
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(np.sum(normal * points, -1)) / (
            np.linalg.norm(normal, axis=-1) * np.linalg.norm(points, axis=-1))
        return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


def grazing(depth: np.ndarray, camera, degrees: float = GRAZING_DEGREES) -> np.ndarray:
    """Pixels whose ray meets the surface more than ``degrees`` away from its normal."""
    angle = ray_normal_angle(depth, camera)
    with np.errstate(invalid="ignore"):
        return angle > degrees  # NaN: False


def out_of_range(depth: np.ndarray, near: float, far: float) -> np.ndarray:
    """Pixels with depth closer than ``near`` or farther than ``far``."""
    ok = valid(depth)
    z = np.where(ok, depth, 0.0)
    return ok & ((z < near) | (z > far))


def random_dropouts(shape, rate: float, rng: np.random.Generator) -> np.ndarray:
    """Each pixel a hole with probability ``rate`` (clipped to [0, 1]); draws from ``rng``
    even at rate 0, so the draws that follow do not depend on the rate."""
    return rng.random(shape) < min(max(rate, 0.0), 1.0)


def physical_holes(depth: np.ndarray, camera, near: float, far: float,
                   edge_threshold: float = EDGE_THRESHOLD,
                   grazing_degrees: float = GRAZING_DEGREES) -> np.ndarray:
    """Edges, grazing angles and range limits together: the holes of the true depth."""
    return (depth_edges(depth, edge_threshold, camera, grazing_degrees)
            | grazing(depth, camera, grazing_degrees)
            | out_of_range(depth, near, far))
