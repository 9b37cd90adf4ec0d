"""Validation views: apart from the test views, and adding them changes nothing else."""

import numpy as np
from skimage import io as skio

from experiments.tasks.scene_task import SceneTask, load_task_scene
from vbgs.data.depth_png import write_depth_png
from vbgs.data.formats import load_replica, load_scene, write_blender
from vbgs.data.scene import Scene, hold_out_validation
from vbgs.data.synthetic import make_scene, object_poses, object_val_poses, room_val_poses

SMALL = dict(size=16, n_train=3, n_test=3)


def _same_frames(a, b):
    assert len(a) == len(b)
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa.rgb, fb.rgb)
        np.testing.assert_array_equal(fa.depth, fb.depth)
        np.testing.assert_array_equal(fa.camera.pose, fb.camera.pose)


def test_synthetic_validation_views_leave_train_and_test_bit_identical():
    for name in ("object", "room"):
        without = make_scene(name, **SMALL, n_val=0)
        with_val = make_scene(name, **SMALL, n_val=3)
        assert without.val == [] and len(with_val.val) == 3
        _same_frames(without.train, with_val.train)
        _same_frames(without.test, with_val.test)


def test_synthetic_validation_views_are_apart_from_test_and_train_views():
    for name in ("object", "room"):
        scene = make_scene(name, **SMALL, n_val=3)
        val = np.stack([f.camera.pose for f in scene.val])  # [3, 4, 4]
        others = np.stack([f.camera.pose for f in scene.train + scene.test])  # [6, 4, 4]
        centres = np.linalg.norm(val[:, None, :3, 3] - others[None, :, :3, 3], axis=-1)
        assert centres.min() > 1e-3  # no validation camera sits where another view is


def test_validation_poses_come_from_their_own_stream():
    _, test = object_poses(4, 3, seed=0)
    val = object_val_poses(3, seed=0)
    assert not any(np.allclose(v, t) for v in val for t in test)
    np.testing.assert_array_equal(object_val_poses(3, seed=0)[1], val[1])  # deterministic
    assert not np.allclose(object_val_poses(3, seed=1)[0], val[0])  # follows the seed
    assert len(room_val_poses(2, seed=0)) == 2


def test_hold_out_validation_positions():
    assert hold_out_validation(list(range(10)), 4) == ([0, 1, 2, 4, 5, 6, 8, 9], [3, 7])
    assert hold_out_validation([1, 2], None) == ([1, 2], [])


def test_scene_without_validation_views_keeps_positional_construction():
    scene = Scene("s", [], [], (np.zeros(3), np.ones(3)))
    assert scene.val == [] and scene.background == (0.0, 0.0, 0.0)


def test_task_scene_carries_n_val_validation_views():
    scene = load_task_scene(SceneTask(frames=2, n_test=1, n_val=2, size=16))
    assert (len(scene.train), len(scene.test), len(scene.val)) == (2, 1, 2)
    assert len(load_task_scene(SceneTask(frames=2, n_test=1, n_val=0, size=16)).val) == 0


def test_blender_round_trip_keeps_validation_views(tmp_path):
    scene = make_scene("object", size=16, n_train=3, n_test=1, n_val=2)
    folder = write_blender(scene, tmp_path / "obj")
    assert (folder / "transforms_val.json").is_file()
    back = load_scene(folder)
    assert (len(back.train), len(back.test), len(back.val)) == (3, 1, 2)
    for a, b in zip(scene.val, back.val, strict=True):
        np.testing.assert_allclose(b.camera.pose, a.camera.pose, atol=1e-12)
    # the loaded dataset, through a task, keeps at most n_val of them
    task = SceneTask(scene=str(folder), frames=3, n_test=1, n_val=1, size=16)
    assert len(load_task_scene(task).val) == 1


def test_blender_without_a_validation_file_holds_out_training_frames(tmp_path):
    scene = make_scene("object", size=16, n_train=4, n_test=1, n_val=0)
    folder = write_blender(scene, tmp_path / "obj")
    back = load_scene(folder, val_every=2)
    assert (len(back.train), len(back.val)) == (2, 2)
    held = [scene.train[1].camera.pose, scene.train[3].camera.pose]
    for pose, frame in zip(held, back.val, strict=True):
        np.testing.assert_allclose(frame.camera.pose, pose, atol=1e-12)
    assert len(load_scene(folder, val_every=None).train) == 4


def _replica(folder, n, h=6, w=8):
    """A tiny Replica-layout folder: frame i's camera sits at x = i."""
    (folder / "results").mkdir(parents=True)
    poses = []
    for i in range(n):
        skio.imsave(folder / f"results/frame{i:06d}.jpg", np.full((h, w, 3), 9 * i, np.uint8),
                    check_contrast=False)
        write_depth_png(folder / f"results/depth{i:06d}.png", np.full((h, w), 1.5), scale=6553.5)
        pose = np.eye(4)
        pose[0, 3] = i
        poses.append(" ".join(f"{x:g}" for x in pose.ravel()))
    (folder / "traj.txt").write_text("\n".join(poses) + "\n")
    return folder


def test_replica_validation_views_are_neither_train_nor_test(tmp_path):
    folder = _replica(tmp_path / "room0", n=8)
    scene = load_replica(folder, test_every=4, val_every=3)
    xs = {name: [round(f.camera.pose[0, 3], 9) for f in getattr(scene, name)]
          for name in ("train", "test", "val")}
    # test: positions 2, 6 (every 4th from 4 // 2); val: every 3rd of the rest (3, 7)
    assert xs == {"train": [0, 1, 4, 5], "test": [2, 6], "val": [3, 7]}
