"""Synthetic RGB-D frames of textured planes, cast analytically (no map, no rasterizer):
the ground of a street (one plane) and the corner of a box (three)."""

from types import SimpleNamespace

import numpy as np
import pytest

from vbgs.data.scene import Frame
from vbgs.render.camera import camera_rays, from_fov, look_at, rigid


def texture(x: np.ndarray) -> np.ndarray:
    """A smooth texture with several scales ``[n, 3]`` of world points ``x [n, 3]``."""
    a, b, c = x[:, 0], x[:, 1], x[:, 2]
    red = 0.5 + 0.25 * np.sin(3.1 * a + 1.3 * b) + 0.15 * np.sin(9.0 * c + 7.0 * a)
    green = 0.5 + 0.25 * np.cos(2.3 * b - 0.7 * c) + 0.15 * np.sin(8.0 * a - 6.0 * b)
    blue = 0.5 + 0.2 * np.sin(1.7 * a + 2.9 * c) + 0.15 * np.cos(7.0 * b + 5.0 * c)
    return np.clip(np.stack([red, green, blue], -1), 0.0, 1.0)


def cast(pose, planes, *, size=64, octant=False) -> Frame:
    """The frame seen from ``pose`` of ``planes`` (``(normal, offset)``: ``n . x = c``),
    nearest hit first; ``octant``: only hits with every coordinate >= 0 count (the
    inside of a box's corner at the origin)."""
    camera = from_fov(size, size, np.radians(60), np.asarray(pose, np.float64))
    rays = camera_rays(camera).reshape(-1, 3)  # unit z: t is the z-depth
    origin = camera.pose[:3, 3]
    dirs = rigid(rays, camera.pose) - origin
    best = np.full(len(rays), np.inf)
    for normal, offset in planes:
        n = np.asarray(normal, np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offset - n @ origin) / (dirs @ n)
        hit = origin + t[:, None] * dirs
        ok = (t > 1e-6) & np.isfinite(t)
        if octant:
            ok &= np.all(hit >= -1e-9, axis=1)
        best = np.where(ok & (t < best), t, best)
    depth = np.where(np.isfinite(best), best, 0.0)
    points = origin + np.where(np.isfinite(best), best, 0.0)[:, None] * dirs
    rgb = np.where(np.isfinite(best)[:, None], texture(points), 0.6)
    return Frame(rgb.reshape(size, size, 3).astype(np.float32),
                 depth.reshape(size, size).astype(np.float32), camera)


GROUND = [((0.0, 0.0, 1.0), 0.0)]  # z = 0
CORNER = [((1.0, 0.0, 0.0), 0.0), ((0.0, 1.0, 0.0), 0.0), ((0.0, 0.0, 1.0), 0.0)]


@pytest.fixture(scope="module")
def street():
    """A camera 1.5 units above the ground looking ahead and down, and its frame."""
    pose = look_at([0.1, -1.0, 1.5], [0.3, 4.0, 0.0])
    return pose, cast(pose, GROUND)


@pytest.fixture(scope="module")
def corner():
    """A camera looking into a box's corner from 3 units away, and its frame."""
    pose = look_at([2.2, 2.0, 1.8], [0.0, 0.0, 0.0])
    return pose, cast(pose, CORNER, octant=True)


@pytest.fixture(scope="module")
def planes():
    """The caster and the planes, for tests that move the camera."""
    return SimpleNamespace(cast=cast, ground=GROUND, corner=CORNER)
