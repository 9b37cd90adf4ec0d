"""Bad dataset files give a one-line error naming the file, never a silently wrong number."""

import json

import numpy as np
import pytest
from skimage import io as skio

from vbgs.data.blender import load_blender
from vbgs.data.depth_png import read_depth_png, write_depth_png
from vbgs.data.images import read_image_file
from vbgs.render.camera import look_at

FLIP = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenGL <-> OpenCV camera axes


def _pose(i):
    return look_at([3.0 * np.cos(i), 3.0 * np.sin(i), 1.0], [0.0, 0.0, 0.2])


def _write_frame(folder, i, h, w, depth=None):
    rgb = np.random.default_rng(i).integers(0, 256, (h, w, 3), dtype=np.uint8)
    (folder / "train").mkdir(parents=True, exist_ok=True)
    skio.imsave(folder / f"train/r_{i}.png", rgb, check_contrast=False)
    depth = np.full((h, w), 2.0) if depth is None else depth
    write_depth_png(folder / f"train/r_{i}_depth.png", depth)
    return {"file_path": f"./train/r_{i}", "transform_matrix": (_pose(i) @ FLIP).tolist()}


def _dataset(folder, sizes, meta):
    frames = [_write_frame(folder, i, h, w) for i, (w, h) in enumerate(sizes)]
    for split in ("train", "test"):
        (folder / f"transforms_{split}.json").write_text(json.dumps({**meta, "frames": frames}))
    return folder


# case 1 ------------------------------------------------------------------------------


def test_8bit_depth_png_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "d.png"
    skio.imsave(path, np.full((4, 5), 200, np.uint8), check_contrast=False)
    with pytest.raises(ValueError, match=r"d\.png: depth PNGs must be 16-bit .* this one is 8-bit"):
        read_depth_png(path)


def test_colour_image_as_depth_is_refused(tmp_path):
    codes = np.arange(20, dtype=np.uint8).reshape(4, 5) * 10
    colour = tmp_path / "colour.png"
    skio.imsave(colour, np.stack([codes, codes, codes + 7], -1), check_contrast=False)
    with pytest.raises(ValueError, match=r"colour\.png: a colour image, not a depth map"):
        read_depth_png(colour)
    grey = tmp_path / "grey.png"  # grey in RGB is read as one channel, then refused as 8-bit
    skio.imsave(grey, np.repeat(codes[..., None], 3, -1), check_contrast=False)
    with pytest.raises(ValueError, match=r"grey\.png: .* this one is 8-bit"):
        read_depth_png(grey)


def test_16bit_depth_png_round_trips(tmp_path):
    depth = np.random.default_rng(0).uniform(0.5, 60.0, (6, 7)).round(3)
    write_depth_png(tmp_path / "d.png", depth)
    np.testing.assert_allclose(read_depth_png(tmp_path / "d.png"), depth, rtol=1e-6)


def test_8bit_depth_in_a_dataset_is_refused(tmp_path):
    folder = _dataset(tmp_path / "ds", [(8, 6)], {"camera_angle_x": 0.8})
    skio.imsave(folder / "train/r_0_depth.png", np.full((6, 8), 200, np.uint8),
                check_contrast=False)
    with pytest.raises(ValueError, match=r"r_0_depth\.png: depth PNGs must be 16-bit"):
        load_blender(folder)


# case 2 ------------------------------------------------------------------------------


def test_frames_of_different_sizes_get_intrinsics_scaled_from_w_h(tmp_path):
    meta = {"fl_x": 20.0, "fl_y": 22.0, "cx": 8.0, "cy": 6.0, "w": 16, "h": 12}
    scene = load_blender(_dataset(tmp_path / "ds", [(16, 12), (32, 24), (8, 12)], meta))
    cams = [f.camera for f in scene.train]
    assert (cams[0].fx, cams[0].fy, cams[0].cx, cams[0].cy) == (20.0, 22.0, 8.0, 6.0)
    assert (cams[1].fx, cams[1].fy, cams[1].cx, cams[1].cy) == (40.0, 44.0, 16.0, 12.0)
    assert (cams[2].fx, cams[2].fy, cams[2].cx, cams[2].cy) == (10.0, 22.0, 4.0, 6.0)
    assert [(c.width, c.height) for c in cams] == [(16, 12), (32, 24), (8, 12)]


def test_per_frame_intrinsics_override_the_file(tmp_path):
    folder = _dataset(tmp_path / "ds", [(16, 12), (16, 12)], {"camera_angle_x": 0.8})
    meta = json.loads((folder / "transforms_train.json").read_text())
    meta["frames"][1].update(fl_x=30.0, w=16, h=12)
    (folder / "transforms_train.json").write_text(json.dumps(meta))
    cams = [f.camera for f in load_blender(folder).train]
    assert cams[0].fx == pytest.approx(8.0 / np.tan(0.4))
    assert cams[1].fx == cams[1].fy == 30.0


def test_angle_intrinsics_follow_each_image_size(tmp_path):
    scene = load_blender(_dataset(tmp_path / "ds", [(16, 12), (32, 24)], {"camera_angle_x": 0.8}))
    fx = [f.camera.fx for f in scene.train]
    assert fx[1] == pytest.approx(2 * fx[0]) and fx[0] == pytest.approx(8.0 / np.tan(0.4))


def test_pixel_intrinsics_without_w_h_and_mixed_sizes_are_refused(tmp_path):
    meta = {"fl_x": 20.0, "cx": 8.0, "cy": 6.0}
    folder = _dataset(tmp_path / "ds", [(16, 12), (32, 24)], meta)
    with pytest.raises(ValueError, match=r"frame 1 \(.*r_1\.png\): image is 32x24 but the "
                                         r"split's first image is 16x12.*add \"w\" and \"h\""):
        load_blender(folder)


# case 8 ------------------------------------------------------------------------------


def test_truncated_png_in_a_dataset_names_the_file(tmp_path):
    folder = _dataset(tmp_path / "ds", [(16, 12), (16, 12)], {"camera_angle_x": 0.8})
    image = folder / "train/r_1.png"
    image.write_bytes(image.read_bytes()[:60])
    with pytest.raises(ValueError, match=r"could not read image file .*r_1\.png"):
        load_blender(folder)
    with pytest.raises(ValueError, match=r"could not read image file .*r_1\.png"):
        read_image_file(image)


# case 10 -----------------------------------------------------------------------------


def test_all_zero_depth_frame_is_named(tmp_path):
    folder = _dataset(tmp_path / "ds", [(16, 12), (16, 12)], {"camera_angle_x": 0.8})
    write_depth_png(folder / "train/r_1_depth.png", np.zeros((12, 16)))
    with pytest.raises(ValueError, match=r"frame 1 .*r_1\.png\): depth is 0 \(missing\) at every "
                                         r"pixel"):
        load_blender(folder)
    assert load_blender(folder, require_depth=False).train[1].depth.max() == 0.0


def test_nan_in_a_pose_is_named(tmp_path):
    folder = _dataset(tmp_path / "ds", [(16, 12), (16, 12)], {"camera_angle_x": 0.8})
    meta = json.loads((folder / "transforms_train.json").read_text())
    meta["frames"][1]["transform_matrix"][0][3] = float("nan")
    (folder / "transforms_train.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"transforms_train.json frame 1: transform_matrix has "
                                         r"1 NaN/inf entries"):
        load_blender(folder)
