"""The "walk" scene: an open trajectory down a street, the sky without depth."""

import numpy as np
import pytest
from scipy import ndimage

from vbgs.data.raycast import camera_rays, cast
from vbgs.data.scene import validate_scene
from vbgs.data.synthetic import (
    WALK_EYE,
    WALK_SKY,
    make_scene,
    render_views,
    scene_primitives,
    walk_poses,
    walk_primitives,
    walk_val_poses,
)

SMALL = dict(size=32, n_train=8, n_test=3)
SKY = np.asarray(WALK_SKY, np.float32)  # the frames are float32


@pytest.fixture(scope="module")
def walk():
    return make_scene("walk", **SMALL, n_val=2)


def _centres(poses):
    return np.stack([np.asarray(p)[:3, 3] for p in poses])  # [n, 3]


def test_scene_is_valid_and_named(walk):
    validate_scene(walk)
    assert walk.name == "walk" and walk.background == WALK_SKY
    assert (len(walk.train), len(walk.test), len(walk.val)) == (8, 3, 2)


def test_trajectory_is_open_and_moves_forward():
    train, _ = walk_poses(60, 8)
    centres = _centres(train)
    from_start = np.linalg.norm(centres - centres[0], axis=1)  # [60]
    # the end is 32 units from the start (WALK_LENGTH), and the walk never turns back
    assert from_start[-1] > 25
    assert np.all(np.diff(from_start) > 0.4)
    steps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert steps.max() < 0.6  # frame i and i + 1 are neighbours: 32 / 59 = 0.54
    np.testing.assert_allclose(centres[:, 2], WALK_EYE)
    # the gaze looks ahead (+x) and wanders left and right so the sides are seen
    gaze = np.stack([p[:3, 2] for p in train])  # [60, 3] camera z axes
    assert gaze[:, 0].min() > 0.85  # within 32 degrees of +x: path heading + wander
    yaw = np.arctan2(gaze[:, 1], gaze[:, 0])
    assert yaw.max() > 0.25 and yaw.min() < -0.25


def test_depth_reaches_far_and_the_sky_has_none(walk):
    prims = scene_primitives("walk")
    depths = np.stack([f.depth for f in walk.train])  # [8, 32, 32]
    assert depths.max() > 30  # the far buildings and the end of the ground
    assert depths[depths > 0].min() > 1.0  # the road ahead of the eye
    for f in walk.train:
        sky = f.depth == 0
        assert 0.1 < sky.mean() < 0.6  # sky in every training frame
        # the centre ray of every depth-0 pixel hits nothing; every other one hits
        t, _ = cast(prims, f.camera.position, camera_rays(f.camera))
        np.testing.assert_array_equal(~np.isfinite(t).reshape(sky.shape), sky)
        # depth-0 pixels away from every surface pixel are pure sky colour (a pixel's
        # colour averages its sub-pixel rays, so silhouette pixels mix in a primitive)
        clear = sky & ~ndimage.binary_dilation(~sky, structure=np.ones((3, 3)))
        assert clear.sum() > 0.5 * sky.sum()
        np.testing.assert_array_equal(f.rgb[clear], np.broadcast_to(SKY, (clear.sum(), 3)))


def test_one_ray_per_pixel_sky_is_exactly_the_sky_colour():
    scene = make_scene("walk", size=24, n_train=3, n_test=1, n_val=0, samples=1)
    for f in scene.train + scene.test:
        sky = f.depth == 0
        assert sky.any()
        np.testing.assert_array_equal(f.rgb[sky], np.broadcast_to(SKY, (sky.sum(), 3)))
        assert not np.any(np.all(f.rgb[~sky] == SKY, axis=-1))


def test_deterministic_under_seed_and_seed_moves_objects(walk):
    again = make_scene("walk", **SMALL, n_val=2)
    for a, b in zip(walk.train + walk.test + walk.val, again.train + again.test + again.val,
                    strict=True):
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.camera.pose, b.camera.pose)
    # the same cameras, the objects of seed 1: every frame's depth changes
    poses = [f.camera.pose for f in walk.train]
    moved = render_views("walk", poses, size=32, seed=1)
    for a, b in zip(walk.train, moved, strict=True):
        changed = a.depth != b.depth
        assert 0.005 < changed.mean() < 0.5  # objects moved; the ground stays
    p0, p1 = walk_primitives(0), walk_primitives(1)
    assert len(p0) == len(p1)
    assert p0[:3] == p1[:3]  # the ground
    assert all(a != b for a, b in zip(p0[3:], p1[3:], strict=True))


def test_test_views_lie_along_the_whole_path_off_it():
    n_train = 30
    train, test = walk_poses(n_train, 8)
    centres, tests = _centres(train), _centres(test)
    gaps = np.linalg.norm(tests[:, None] - centres[None], axis=-1)  # [8, 30]
    nearest = gaps.argmin(1)
    # one test view in each eighth of the stream: from its first frames to its last
    assert nearest.min() <= 0.15 * n_train and nearest.max() >= 0.85 * n_train
    assert len(set(nearest)) == 8
    # in the order of stretches 0, 2, 4, 6, 1, 3, 5, 7: the first four span the path too
    assert np.all(np.diff(nearest[:4]) > 0) and np.all(np.diff(nearest[4:]) > 0)
    assert nearest[0] <= 0.15 * n_train and nearest[3] >= 0.6 * n_train
    assert gaps.min(1).min() > 0.1  # off the training path
    assert np.all(np.abs(tests[:, 2] - WALK_EYE) <= 0.3)
    # validation views are drawn the same way: along the whole path, apart from the test ones
    val = _centres(walk_val_poses(8))
    val_nearest = np.linalg.norm(val[:, None] - centres[None], axis=-1).argmin(1)
    assert val_nearest.min() <= 0.15 * n_train and val_nearest.max() >= 0.85 * n_train
    assert np.linalg.norm(val[:, None] - tests[None], axis=-1).min() > 1e-3


def test_validation_views_leave_train_and_test_bit_identical():
    without = make_scene("walk", size=16, n_train=3, n_test=3, n_val=0)
    with_val = make_scene("walk", size=16, n_train=3, n_test=3, n_val=3)
    assert without.val == [] and len(with_val.val) == 3
    for a, b in zip(without.train + without.test, with_val.train + with_val.test, strict=True):
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.camera.pose, b.camera.pose)
    np.testing.assert_array_equal(walk_val_poses(3, seed=0)[2], with_val.val[2].camera.pose)
    assert not np.allclose(walk_val_poses(3, seed=1)[0], walk_val_poses(3, seed=0)[0])
