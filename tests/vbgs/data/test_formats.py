import json

import numpy as np
import pytest
from skimage import io as skio

from vbgs.data.depth_png import write_depth_png
from vbgs.data.formats import (
    REPLICA_INTRINSICS,
    Intrinsics,
    detect_format,
    load_replica,
    load_scene,
    load_tum,
    quaternion_to_matrix,
    write_blender,
)
from vbgs.data.synthetic import make_scene
from vbgs.render.camera import look_at

FLIP = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenGL <-> OpenCV camera axes


def _pose(i):
    return look_at([3.0 * np.cos(i), 3.0 * np.sin(i), 1.0 + 0.1 * i], [0.0, 0.0, 0.2])


def _depth(h, w, i):
    rng = np.random.default_rng(i)
    depth = np.round(rng.uniform(0.5, 4.0, (h, w)), 3)
    depth[0, 0] = 0.0  # one missing pixel
    return depth


def _rgb8(h, w, i):
    return np.random.default_rng(100 + i).integers(0, 256, (h, w, 3), dtype=np.uint8)


def _smooth8(h, w, i):
    """A smooth colour ramp that JPEG keeps nearly intact."""
    v, u = np.mgrid[0:h, 0:w] / max(h, w)
    rgb = np.stack([u, v, 0.5 + 0.4 * np.sin(3 * u + i)], -1)
    return np.round(255 * rgb).astype(np.uint8)


# --------------------------------------------------------------------------- Blender


def _blender(folder, n=3, h=12, w=16, angle=0.8):
    frames = []
    for i in range(n):
        rgba = np.concatenate([_rgb8(h, w, i), np.full((h, w, 1), 255, np.uint8)], -1)
        rgba[1, 2, 3] = 0  # transparent -> background
        (folder / "train").mkdir(parents=True, exist_ok=True)
        skio.imsave(folder / f"train/r_{i}.png", rgba, check_contrast=False)
        if i == 2:
            np.save(folder / f"train/r_{i}_depth.npy", _depth(h, w, i))
        else:
            write_depth_png(folder / f"train/r_{i}_depth.png", _depth(h, w, i))
        path = f"./train/r_{i}" if i else f"train/r_{i}.png"  # with and without extension
        frames.append({"file_path": path, "transform_matrix": (_pose(i) @ FLIP).tolist()})
    meta = {"camera_angle_x": angle, "frames": frames}
    (folder / "transforms_train.json").write_text(json.dumps(meta))
    (folder / "transforms_val.json").write_text(json.dumps({**meta, "frames": frames[:1]}))
    return folder


def test_blender_loader_reads_poses_intrinsics_depth_and_alpha(tmp_path):
    scene = load_scene(_blender(tmp_path / "lego"))
    assert scene.name == "lego" and len(scene.train) == 3 and len(scene.test) == 1
    assert scene.background == (1.0, 1.0, 1.0)
    for i, f in enumerate(scene.train):
        np.testing.assert_allclose(f.camera.pose, _pose(i), atol=1e-12)
        assert f.camera.fx == pytest.approx(8.0 / np.tan(0.4)) and f.camera.fy == f.camera.fx
        assert (f.camera.cx, f.camera.cy, f.camera.width, f.camera.height) == (8.0, 6.0, 16, 12)
        np.testing.assert_allclose(f.depth, _depth(12, 16, i), atol=1e-6)
        np.testing.assert_allclose(f.rgb[1, 2], [1.0, 1.0, 1.0])  # alpha 0 -> white
        np.testing.assert_allclose(f.rgb[5, 5], _rgb8(12, 16, i)[5, 5] / 255.0, atol=1e-6)
    lo, hi = scene.bounds
    assert np.all(lo < hi)


def test_blender_background_stride_and_size(tmp_path):
    folder = _blender(tmp_path / "s")
    scene = load_scene(folder, background=(0.0, 0.0, 0.0), stride=2, size=8)
    assert len(scene.train) == 2
    f = scene.train[1]
    np.testing.assert_allclose(f.camera.pose, _pose(2), atol=1e-12)
    assert f.rgb.shape == (6, 8, 3) and f.depth.shape == (6, 8)
    assert f.camera.fx == pytest.approx(4.0 / np.tan(0.4)) and f.camera.cx == 4.0
    np.testing.assert_allclose(f.depth, _depth(12, 16, 2)[1::2, 1::2], atol=1e-6)  # nearest
    assert scene.background == (0.0, 0.0, 0.0)


def test_blender_missing_files_are_named(tmp_path):
    folder = _blender(tmp_path / "a")
    (folder / "train/r_1.png").unlink()
    with pytest.raises(FileNotFoundError, match="r_1"):
        load_scene(folder)
    folder = _blender(tmp_path / "b")
    (folder / "train/r_0_depth.png").unlink()
    with pytest.raises(FileNotFoundError, match="r_0_depth.png"):
        load_scene(folder)
    no_depth = load_scene(folder, require_depth=False)
    assert np.all(no_depth.train[0].depth == 0)
    (folder / "transforms_train.json").unlink()
    with pytest.raises(FileNotFoundError, match="transforms_train.json"):
        load_scene(folder)
    folder = _blender(tmp_path / "c")
    (folder / "transforms_val.json").unlink()
    with pytest.raises(FileNotFoundError, match="transforms_test.json"):
        load_scene(folder)
    folder = _blender(tmp_path / "d")
    (folder / "transforms_train.json").write_text("{not json")
    with pytest.raises(ValueError, match="transforms_train.json"):
        load_scene(folder)


def test_write_blender_round_trip(tmp_path):
    scene = make_scene("object", size=24, n_train=3, n_test=2)
    folder = write_blender(scene, tmp_path / "obj")
    for name in (
        "transforms_train.json",
        "transforms_test.json",
        "train/r_000.png",
        "train/r_000_depth.png",
        "test/r_001.png",
        "test/r_001_depth.png",
    ):
        assert (folder / name).is_file(), name
    meta = json.loads((folder / "transforms_train.json").read_text())
    np.testing.assert_allclose(
        meta["frames"][0]["transform_matrix"], scene.train[0].camera.pose @ FLIP
    )
    back = load_scene(folder)
    assert len(back.train) == 3 and len(back.test) == 2
    for a, b in zip(scene.train + scene.test, back.train + back.test, strict=True):
        np.testing.assert_allclose(b.camera.pose, a.camera.pose, atol=1e-12)
        for key in ("fx", "fy", "cx", "cy", "width", "height"):
            assert getattr(b.camera, key) == pytest.approx(getattr(a.camera, key))
        np.testing.assert_allclose(b.depth, a.depth, atol=5e-4 + 1e-6)
        np.testing.assert_array_equal(b.depth == 0, a.depth == 0)
        np.testing.assert_allclose(b.rgb, a.rgb, atol=0.5 / 255 + 1e-6)


# --------------------------------------------------------------------------- Replica


def _replica(folder, n=6, h=34, w=60):
    (folder / "results").mkdir(parents=True)
    for i in range(n):
        skio.imsave(folder / f"results/frame{i:06d}.jpg", _smooth8(h, w, i), check_contrast=False)
        write_depth_png(folder / f"results/depth{i:06d}.png", _depth(h, w, i), scale=6553.5)
    lines = [" ".join(f"{x:.17g}" for x in _pose(i).ravel()) for i in range(n)]
    (folder / "traj.txt").write_text("\n".join(lines) + "\n")
    return folder


def test_replica_loader(tmp_path):
    folder = _replica(tmp_path / "room0")
    assert detect_format(folder) == "replica"
    scene = load_scene(folder, test_every=3)
    assert [f.camera.pose[0, 3] for f in scene.test] == [_pose(1)[0, 3], _pose(4)[0, 3]]
    train_ids = [0, 2, 3, 5]
    for i, f in zip(train_ids, scene.train, strict=True):
        np.testing.assert_allclose(f.camera.pose, _pose(i), atol=1e-12)
        np.testing.assert_allclose(f.depth, _depth(34, 60, i), atol=1 / 6553.5)
        assert np.abs(f.rgb - _smooth8(34, 60, i) / 255.0).mean() < 0.02  # jpeg
    cam = scene.train[0].camera  # defaults rescaled from 1200 x 680 to 60 x 34
    assert cam.fx == pytest.approx(30.0) and cam.fy == pytest.approx(30.0)
    assert cam.cx == pytest.approx(30.0) and cam.cy == pytest.approx(17.0)


def test_replica_options(tmp_path):
    folder = _replica(tmp_path / "r")
    scene = load_replica(folder, test_every=None, max_frames=2, stride=2, size=30)
    assert len(scene.train) == 2 and scene.test == []
    np.testing.assert_allclose(scene.train[1].camera.pose, _pose(2))
    assert scene.train[0].rgb.shape == (17, 30, 3)
    assert scene.train[0].camera.fx == pytest.approx(15.0)
    own = Intrinsics(50.0, 40.0, 29.5, 16.5, 60, 34)
    cam = load_replica(folder, intrinsics=own).train[0].camera
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (50.0, 40.0, 30.0, 17.0)
    assert REPLICA_INTRINSICS.width == 1200


def test_replica_malformed(tmp_path):
    folder = _replica(tmp_path / "a")
    lines = (folder / "traj.txt").read_text().splitlines()
    (folder / "traj.txt").write_text("\n".join(lines[:-1]))
    with pytest.raises(ValueError, match=r"traj.txt has 5 poses for 6"):
        load_scene(folder)
    lines[1] = " ".join(lines[1].split()[:15])
    (folder / "traj.txt").write_text("\n".join(lines))
    with pytest.raises(ValueError, match="traj.txt line 2: expected 16 numbers"):
        load_scene(folder)
    folder = _replica(tmp_path / "b")
    (folder / "results/depth000003.png").unlink()
    with pytest.raises(FileNotFoundError, match="depth000003.png"):
        load_scene(folder)
    (folder / "traj.txt").unlink()
    with pytest.raises(FileNotFoundError, match="traj.txt"):
        load_scene(folder)


# --------------------------------------------------------------------------- TUM


def _tum(folder, h=24, w=32):
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    rgb_lines, depth_lines, gt_lines = ["# color images", "# timestamp filename"], ["# depth"], []
    for i in range(5):
        t = 100.0 + 0.1 * i
        skio.imsave(folder / f"rgb/{t:.6f}.png", _rgb8(h, w, i), check_contrast=False)
        rgb_lines.append(f"{t:.6f} rgb/{t:.6f}.png")
        if i != 3:  # frame 3 has no depth within the tolerance
            td = t + 0.007
            write_depth_png(folder / f"depth/{td:.6f}.png", _depth(h, w, i), scale=5000.0)
            depth_lines.append(f"{td:.6f} depth/{td:.6f}.png")
    for k in range(60):  # poses at 100 Hz, rotating about z
        t, angle = 99.9 + 0.01 * k, 0.05 * k
        q = (0.0, 0.0, np.sin(angle / 2), np.cos(angle / 2))
        gt_lines.append(f"{t:.4f} {k * 0.01} 0.5 1.5 " + " ".join(f"{x:.17g}" for x in q))
    (folder / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (folder / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    (folder / "groundtruth.txt").write_text("# ground truth\n" + "\n".join(gt_lines) + "\n")
    return folder


def test_tum_loader_associates_by_timestamp(tmp_path):
    folder = _tum(tmp_path / "fr1")
    assert detect_format(folder) == "tum"
    scene = load_tum(folder, test_every=None)
    assert len(scene.train) == 4  # frame 3 dropped
    for i, f in zip([0, 1, 2, 4], scene.train, strict=True):
        k = 10 + 10 * i  # the pose at time 100 + 0.1 i
        rot = quaternion_to_matrix(0.0, 0.0, np.sin(0.025 * k), np.cos(0.025 * k))
        np.testing.assert_allclose(f.camera.pose[:3, :3], rot, atol=1e-12)
        np.testing.assert_allclose(f.camera.pose[:3, 3], [k * 0.01, 0.5, 1.5], atol=1e-12)
        np.testing.assert_allclose(f.depth, _depth(24, 32, i), atol=1 / 5000)
        np.testing.assert_allclose(f.rgb, _rgb8(24, 32, i) / 255.0, atol=1e-6)
    cam = scene.train[0].camera  # freiburg1 defaults rescaled from 640 x 480 to 32 x 24
    assert cam.fx == pytest.approx(517.3 / 20) and cam.cx == pytest.approx(319.1 / 20)
    assert cam.fy == pytest.approx(516.5 / 20) and cam.cy == pytest.approx(255.8 / 20)


def test_tum_tolerance_and_errors(tmp_path):
    folder = _tum(tmp_path / "a")
    with pytest.raises(ValueError, match="max_time_diff"):
        load_tum(folder, max_time_diff=0.001)
    scene = load_tum(folder, test_every=2)
    assert len(scene.train) == 2 and len(scene.test) == 2
    (folder / "groundtruth.txt").unlink()
    with pytest.raises(FileNotFoundError, match="groundtruth.txt"):
        load_scene(folder)
    folder = _tum(tmp_path / "b")
    with (folder / "rgb.txt").open("a") as fh:
        fh.write("100.9 rgb/missing.png extra\n")
    with pytest.raises(ValueError, match="rgb.txt line"):
        load_scene(folder)


def test_quaternion_to_matrix():
    rot = quaternion_to_matrix(0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4))  # 90 deg about z
    np.testing.assert_allclose(rot, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    rot = quaternion_to_matrix(0.2, -0.4, 0.1, 0.9)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)


# --------------------------------------------------------------------------- entry point


def test_load_scene_names_and_unknown_folders(tmp_path):
    scene = load_scene("room", size=8, n_train=2, n_test=1)
    assert scene.name == "room" and len(scene.train) == 2
    with pytest.raises(FileNotFoundError, match="object, room"):
        load_scene(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="transforms_train.json"):
        load_scene(tmp_path / "empty")
    with pytest.raises(ValueError, match="blender, replica, tum"):
        load_scene(tmp_path / "empty", format="colmap")
