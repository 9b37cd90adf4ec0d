"""The "walk-long" scene: the walk's street continued, so a 200-frame stream meets new ground."""

import numpy as np
import pytest

from vbgs.data.synthetic import (
    WALK_BLOCK,
    WALK_FAR,
    WALK_LENGTH,
    WALK_LONG_FRAMES,
    WALK_LONG_LENGTH,
    WALK_SKY,
    make_scene,
    render_views,
    scene_primitives,
    walk_poses,
    walk_primitives,
)
from vbgs.render.camera import unproject


@pytest.fixture(scope="module")
def long_walk():
    """All 200 training frames, tiny (16 px, one ray a pixel): what the stream walks through."""
    return make_scene("walk-long", size=16, n_train=WALK_LONG_FRAMES, n_test=8, n_val=2,
                      samples=1)


def _centres(poses):
    return np.stack([np.asarray(p)[:3, 3] for p in poses])  # [n, 3]


def test_registered_and_valid(long_walk):
    assert long_walk.name == "walk-long" and long_walk.background == WALK_SKY
    assert (len(long_walk.train), len(long_walk.test), len(long_walk.val)) == (200, 8, 2)
    # render_views knows its field of view and sky: the same frames from the same poses
    again = render_views("walk-long", [long_walk.train[150].camera.pose], size=16, samples=1)
    np.testing.assert_array_equal(again[0].rgb, long_walk.train[150].rgb)
    np.testing.assert_array_equal(again[0].depth, long_walk.train[150].depth)
    assert len(scene_primitives("walk-long")) == len(walk_primitives(0, WALK_LONG_LENGTH))


def test_steps_as_far_apart_as_the_walks():
    """200 frames over 107.9 units step as the walk's 60 over 32: its first 60 frames are
    the walk's 60 (the weave and the wandering gaze run at the walk's rate per unit)."""
    walk, _ = walk_poses(60, 8)
    long, _ = walk_poses(WALK_LONG_FRAMES, 8, length=WALK_LONG_LENGTH)
    np.testing.assert_allclose(np.stack(long[:60]), np.stack(walk), atol=1e-12)
    centres = _centres(long)
    np.testing.assert_allclose(centres[-1, 0], 107.932, atol=1e-3)
    steps = np.diff(centres[:, 0])
    np.testing.assert_allclose(steps, WALK_LENGTH / 59)  # x advances 0.542 a frame
    assert np.linalg.norm(np.diff(centres, axis=0), axis=1).max() < 0.56
    # the test views are spread along the whole longer path
    tests = _centres(walk_poses(WALK_LONG_FRAMES, 8, length=WALK_LONG_LENGTH)[1])
    assert tests[:, 0].min() < WALK_LONG_LENGTH / 8 and tests[:, 0].max() > 0.85 * WALK_LONG_LENGTH


def test_the_first_block_is_the_walks_street_and_the_far_buildings_move_out():
    for seed in (0, 1):
        walk, long = walk_primitives(seed), walk_primitives(seed, WALK_LONG_LENGTH)
        n_far = 4 * len(WALK_FAR)  # four walls each
        street = slice(3, len(walk) - n_far)  # after the three ground quads
        assert long[street] == walk[street]  # every house, tree, rock and post
        # the ground runs as far past the longer path's end
        assert long[0].corner == walk[0].corner
        np.testing.assert_allclose(long[0].edge_u[0] - walk[0].edge_u[0], WALK_LONG_LENGTH - WALK_LENGTH)
        far_walk = np.stack([q.corner for q in walk[-n_far:]])
        far_long = np.stack([q.corner for q in long[len(walk) - n_far:len(walk)]])
        np.testing.assert_allclose(far_long - far_walk,
                                   np.broadcast_to([WALK_LONG_LENGTH - WALK_LENGTH, 0, 0],
                                                   far_walk.shape), atol=1e-4)
        # and the street repeats: two more blocks of the walk's objects
        assert len(long) - len(walk) == 2 * (len(walk) - 3 - n_far)
    assert 2 * WALK_BLOCK < WALK_LONG_LENGTH <= 3 * WALK_BLOCK


def test_later_frames_see_ground_the_first_ones_did_not(long_walk):
    """What the last 20 frames see within 15 units, the walk's 60 frames (the first 60
    here) saw from more than 60 units away, if at all."""
    near = []
    for f in long_walk.train[180:]:
        xyz, _ = unproject(f.camera, f.rgb, f.depth)
        xyz = np.asarray(xyz)
        near.append(xyz[np.linalg.norm(xyz - f.camera.position, axis=1) < 15.0])
    near = np.concatenate(near)  # [n, 3]
    assert len(near) > 1000
    first = _centres([f.camera.pose for f in long_walk.train[:60]])
    gap = np.linalg.norm(near[:, None] - first[None], axis=-1).min()
    assert gap > 60.0  # measured 67.3 (x = 99.3 against the first frames' 32.0)
    assert near[:, 0].min() > 95.0 and near[:, 0].max() > 115.0  # the third block's street


def test_open_street_all_the_way(long_walk):
    depths = np.stack([f.depth for f in long_walk.train])  # [200, 16, 16]
    assert depths[depths > 0].min() > 1.0  # no object in front of the eye anywhere
    assert depths.max() > 100  # the first frames see the far buildings past the end
    sky = (depths == 0).mean(axis=(1, 2))
    assert sky.min() > 0.1 and sky.max() < 0.6  # sky in every frame
