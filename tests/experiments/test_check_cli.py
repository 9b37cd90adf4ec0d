"""`python -m experiments.run check`: a Blender folder written from the synthetic room,
corrupted each way a user's file goes wrong; the doctor fails (exit 2, an error field)
and names the cause; fit-scene refuses the cheap failures and warns on the rest."""

import json
import shutil

import numpy as np
import pytest

from experiments.run import main
from experiments.scene_task import SceneTask, load_task_scene
from vbgs.data.blender import write_blender
from vbgs.data.depth_png import read_depth_png, write_depth_png
from vbgs.data.synthetic import room_scene
from vbgs.data.writers import write_replica

GL = np.diag([1.0, -1, -1, 1])


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return write_blender(room_scene(size=32, n_train=16, n_test=3, n_val=2, seed=0),
                         tmp_path_factory.mktemp("doctor") / "room")


def corrupted(clean, tmp_path, kind):
    out = tmp_path / kind
    shutil.copytree(clean, out)
    for split in ("train", "test", "val"):
        path = out / f"transforms_{split}.json"
        meta = json.loads(path.read_text())
        for f in meta["frames"]:
            m = np.asarray(f["transform_matrix"])
            m = {"w2c": np.linalg.inv, "axes": lambda m: m @ GL}.get(kind, lambda m: m)(m)
            if kind == "mm":
                m[:3, 3] *= 1000
            f["transform_matrix"] = m.tolist()
        path.write_text(json.dumps(meta))
    if kind == "metres-png":
        for png in out.glob("*/*_depth.png"):
            write_depth_png(png, np.round(read_depth_png(png)), 1.0)
    return out


def check(argv, capsys):
    code = main(["check", *argv, "--size", "32", "--json"])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return code, json.loads(out.strip().splitlines()[-1]), err


def test_the_clean_folder_is_healthy(clean, capsys):
    code, report, err = check(["--scene", str(clean)], capsys)
    assert code == 0 and report["healthy"] and not err
    assert report["agreement"] > 0.8 and report["fix"] is None
    assert report["intrinsics_from"] == "transforms_*.json" and report["depth_scale"] == 1000


@pytest.mark.parametrize("kind, failed, cause", [
    ("w2c", "consistency", "the file's poses are world-to-camera: invert each 4x4"),
    ("axes", "consistency", "multiply each pose on the right by diag(1, -1, -1, 1)"),
    ("mm", "depth scale", "divide each pose's translation by 1000"),
    ("metres-png", "depth codes", "depth in metres written as whole numbers to a 16-bit PNG"),
])
def test_the_doctor_names_the_cause(clean, tmp_path, capsys, kind, failed, cause):
    code, report, err = check(["--scene", str(corrupted(clean, tmp_path, kind))], capsys)
    assert code == 2 and not report["healthy"]
    assert report["error"].startswith(f"{failed}: ") and cause in report["error"]
    assert err.startswith("error: ") and cause in err and err.count("\n") == 1


def test_fit_scene_refuses_the_cheap_failures_before_any_work(clean, tmp_path, capsys):
    for kind, words in (("mm", "depth scale"), ("metres-png", "depth codes")):
        assert main(["fit-scene", "--scene", str(corrupted(clean, tmp_path, kind)),
                     "--size", "32", "--components", "100", "--json"]) == 2
        out, err = capsys.readouterr()
        assert words in json.loads(out.strip().splitlines()[-1])["error"]
        assert err.count("\n") == 1


def test_fit_scene_warns_on_views_that_disagree_and_says_what_it_used(clean, tmp_path,
                                                                      capsys):
    """Consistency is a warning (views may differ for reasons the doctor cannot see); the
    record names the camera and depth scale that ran."""
    assert main(["fit-scene", "--scene", str(corrupted(clean, tmp_path, "w2c")), "--size", "32",
                 "--components", "300", "--frames", "6", "--depth-scale", "1000",
                 "--json"]) == 0
    out, err = capsys.readouterr()
    assert "warning: consistency: only" in err and "world-to-camera" in err
    r = json.loads(out.strip().splitlines()[-1])
    assert r["depth_scale"] == 1000 and r["depth_scale_from"] == "--depth-scale"
    assert r["intrinsics_from"] == "transforms_*.json" and len(r["intrinsics"]) == 4


def test_frames_n_scores_only_test_views_near_the_trained_frames(tmp_path, capsys):
    """A Replica trajectory of 24 frames (3 test views, one every 8th) trained on its first
    6: the views from the rest of the trajectory are not scored, and the record says so."""
    scene = room_scene(size=24, n_train=24, n_test=1, n_val=0, seed=0)
    folder = write_replica(scene.train, tmp_path / "room0")
    task = SceneTask(scene=str(folder), frames=6, size=24, n_val=0)
    loaded = load_task_scene(task)
    assert len(loaded.train) == 6 and len(loaded.test) == 1
    assert loaded.record["test_views_outside_span"] == 2
    assert "2 of 3 test views lie outside the span" in capsys.readouterr().err
    whole = load_task_scene(SceneTask(scene=str(folder), size=24, n_val=0))
    assert len(whole.test) == 3 and "test_views_outside_span" not in whole.record
