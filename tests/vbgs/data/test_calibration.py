"""Intrinsics and depth scales: given, from the folder, or the format's presets; and
the record says which."""

import json

import numpy as np
import pytest

from vbgs.data.calibration import (
    REPLICA_INTRINSICS,
    TUM_PRESETS,
    check_depth_scale,
    check_intrinsics,
    tum_preset,
)
from vbgs.data.formats import load_replica, load_tum
from vbgs.data.synthetic import room_scene
from vbgs.data.writers import write_replica, write_tum


@pytest.fixture(scope="module")
def frames():
    return room_scene(size=24, n_train=4, n_test=1, n_val=0, seed=0).train


def test_intrinsics_text_and_numbers():
    assert check_intrinsics("517.3,516.5,318.6,255.3") == (517.3, 516.5, 318.6, 255.3, None, None)
    for bad, words in (("1,2,3", "four numbers"), ("a,b,c,d", "four numbers"),
                       ("0,500,320,240", "must be > 0"), ("500,500,-1,240", ">= 0"),
                       ("nan,500,320,240", "finite")):
        with pytest.raises(ValueError, match=words):
            check_intrinsics(bad)


@pytest.mark.parametrize("scale", [0, -1000, float("nan"), float("inf"), "1000", True])
def test_depth_scale_must_be_a_positive_number(scale):
    with pytest.raises(ValueError, match="depth-scale"):
        check_depth_scale(scale)


@pytest.mark.parametrize("name, preset", [
    ("rgbd_dataset_freiburg1_xyz", "fr1"), ("rgbd_dataset_freiburg2_desk", "fr2"),
    ("freiburg3_long_office_household", "fr3"), ("fr2_pioneer", "fr2"), ("my_scan", None),
    ("fr12", None),
])
def test_tum_preset_from_the_folder_name(tmp_path, name, preset):
    assert tum_preset(tmp_path / name) == preset


def test_replica_reads_cam_params_beside_it(tmp_path, frames):
    folder = write_replica(frames, tmp_path / "room0")
    scene = load_replica(folder, test_every=None, val_every=None)
    cam = scene.train[0].camera
    assert (cam.fx, cam.cx) == pytest.approx((frames[0].camera.fx, frames[0].camera.cx))
    assert scene.record["intrinsics_from"].endswith("cam_params.json")
    assert scene.record["depth_scale"] == 6553.5
    # the SLAM benchmarks keep it one level up, beside the scene folders
    (folder / "cam_params.json").rename(tmp_path / "cam_params.json")
    assert load_replica(folder, test_every=None).record["intrinsics_from"] == str(
        tmp_path / "cam_params.json")
    (tmp_path / "cam_params.json").unlink()
    scene = load_replica(folder, test_every=None)
    assert scene.record["intrinsics_from"].startswith("Replica default")
    sx = 24 / REPLICA_INTRINSICS.width
    assert scene.train[0].camera.fx == pytest.approx(REPLICA_INTRINSICS.fx * sx)
    given = load_replica(folder, test_every=None, intrinsics="30,30,11.5,11.5", depth_scale=6553.5)
    assert given.train[0].camera.fx == 30 and given.record["intrinsics_from"] == "--intrinsics"


def test_a_malformed_cam_params_is_named(tmp_path, frames):
    folder = write_replica(frames, tmp_path / "room0")
    (folder / "cam_params.json").write_text(json.dumps({"camera": {"w": 24}}))
    with pytest.raises(ValueError, match="cam_params.json: expected"):
        load_replica(folder)
    (folder / "cam_params.json").write_text(json.dumps({"camera": {
        "w": 24, "h": 24, "fx": 20, "fy": 20, "cx": 12, "cy": 12, "scale": 0}}))
    with pytest.raises(ValueError, match="camera.scale must be > 0"):
        load_replica(folder)


@pytest.mark.parametrize("name, preset", [("rgbd_dataset_freiburg2_x", "fr2"),
                                          ("rgbd_dataset_freiburg3_x", "fr3"),
                                          ("unnamed", "fr1")])
def test_tum_intrinsics_follow_the_sensor(tmp_path, frames, name, preset):
    scene = load_tum(write_tum(frames, tmp_path / name), test_every=None, val_every=None)
    want = TUM_PRESETS[preset]
    assert scene.train[0].camera.fx == pytest.approx(want.fx * 24 / 640)
    assert preset in scene.record["intrinsics_from"]
    assert np.isclose(scene.record["depth_scale"], 5000)
