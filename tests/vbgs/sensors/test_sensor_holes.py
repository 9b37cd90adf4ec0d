"""Where the active sensors leave holes: depth edges, grazing angles, range limits and
2 % at random; never on a smooth surface the sensor can see, at any resolution."""

import numpy as np
import pytest

from vbgs.render.camera import Camera
from vbgs.sensors import Kinect, RealSense, simulate
from vbgs.sensors.holes import depth_edges, ray_normal_angle


def camera(size: int = 64, focal: float = 100.0) -> Camera:
    return Camera(focal, focal, size / 2, size / 2, size, size, np.eye(4))


def tilted(cam: Camera, degrees: float, through: float = 2.0):
    """A plane through ``(0, 0, through)`` whose normal is turned ``degrees`` about the
    camera's y axis: its depth ``[h, w]`` and the true ray-to-normal angle (degrees)."""
    t = np.radians(degrees)
    normal = np.array([np.sin(t), 0.0, -np.cos(t)])
    u, v = np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5
    rays = np.stack(np.broadcast_arrays(((u - cam.cx) / cam.fx)[None, :],
                                        ((v - cam.cy) / cam.fy)[:, None], 1.0), -1)
    depth = (normal @ [0.0, 0.0, through]) / (rays @ normal)
    cos = np.abs(rays @ normal) / np.linalg.norm(rays, axis=-1)
    return depth.astype(np.float32), np.degrees(np.arccos(cos))


@pytest.mark.parametrize("name", ["kinect", "realsense"])
def test_holes_at_a_depth_edge_on_both_sides(name):
    """A step from 1.0 to 1.5 m between columns 31 and 32: at level 0 (no noise, no
    random holes) exactly those two columns are holes; elsewhere the depth is exact."""
    cam = camera()
    depth = np.full((64, 64), 1.0, np.float32)
    depth[:, 32:] = 1.5
    out = simulate(name, depth, cam, seed=0, level=0.0)
    holes = out == 0
    assert holes[:, 31:33].all() and not holes[:, :31].any() and not holes[:, 33:].any()
    np.testing.assert_array_equal(out[~holes], depth[~holes])


@pytest.mark.parametrize("name", ["kinect", "realsense"])
def test_a_smooth_plane_has_only_the_random_holes(name):
    cam = camera(128, 200.0)
    depth = np.full((128, 128), 2.0, np.float32)
    assert not (simulate(name, depth, cam, seed=0, level=0.0) == 0).any()
    share = np.mean(simulate(name, depth, cam, seed=0) == 0)
    assert 0.015 < share < 0.025  # 2 % of 16,384 pixels: 328 +- 18
    share2 = np.mean(simulate(name, depth, cam, seed=0, level=2.0) == 0)
    assert 0.033 < share2 < 0.047  # the level scales the random rate: 4 %


def test_an_inclined_plane_at_low_resolution_is_no_edge():
    """At 32 px (f = 44 px), 2-5 m away, a plane seen at 30-70 degrees changes by 4 to
    23 cm per pixel, mostly more than the 5 cm edge threshold, yet it is one smooth
    surface the sensor sees."""
    cam = camera(32, 44.0)
    depth, angle = tilted(cam, 50.0, through=3.0)
    jumps = np.abs(np.diff(depth.astype(np.float64), axis=1))
    assert np.mean(jumps > 0.05) > 0.7 and angle.max() < 71
    assert not depth_edges(depth, 0.05, cam).any()
    assert depth_edges(depth, 0.05).any()  # the plain threshold alone would cut it
    assert not (simulate("realsense", depth, cam, seed=0, level=0.0) == 0).any()


@pytest.mark.parametrize("model", [RealSense(), Kinect(far=10.0)])
def test_a_grazing_plane_gets_holes(model):
    """A plane turned 76 degrees, seen over a 36 degree field of view: the ray meets it
    at 67 to 85 degrees from its normal. Beyond 75 degrees it is a hole."""
    cam = camera(64, 200.0)
    depth, angle = tilted(cam, 76.0)
    assert angle.min() < 68 and angle.max() > 84
    estimated = ray_normal_angle(depth, cam)
    assert np.nanmax(np.abs(estimated - angle)) < 0.5  # the normal from the depth map
    out = model.simulate(depth, cam, np.random.default_rng(0), level=0.0)
    assert (out[angle > 76] == 0).all() and (out[angle < 74] > 0).all()
    assert 0.3 < np.mean(out == 0) < 0.7


def test_range_limits():
    cam = camera()
    for z, kinect_kept, realsense_kept in ((0.3, False, True), (0.15, False, False),
                                           (4.4, True, True), (5.0, False, True),
                                           (11.0, False, False)):
        depth = np.full((64, 64), z, np.float32)
        assert (simulate("kinect", depth, cam, seed=0, level=0.0) > 0).all() == kinect_kept, z
        assert (simulate("realsense", depth, cam, seed=0, level=0.0) > 0).all() == realsense_kept, z


def test_missing_depth_stays_missing_and_silhouettes_are_edges():
    """NaN, inf and 0 are no depth: 0 out; the object pixels beside them are holes."""
    cam = camera()
    depth = np.zeros((64, 64), np.float32)
    depth[20:40, 20:40] = 2.0
    depth[0, 0], depth[0, 1] = np.nan, np.inf
    out = simulate("kinect", depth, cam, seed=0, level=0.0)
    assert (out[~(depth > 0)] == 0).all()
    ring = np.zeros((64, 64), bool)
    ring[20:40, 20:40] = True
    ring[21:39, 21:39] = False
    assert (out[ring] == 0).all() and (out[21:39, 21:39] == 2.0).all()
