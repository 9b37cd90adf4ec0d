"""`python -m experiments.run check` end to end on a Blender folder written from the
synthetic room; fit-scene's consistency warning; --frames N and the test views it scores.
(Each corruption and the cause the doctor names: tests/experiments/test_bad_input.py.)"""

import json
import shutil

import numpy as np
import pytest

import experiments.scene_task as scene_task
from experiments.run import main
from experiments.scene_task import SceneTask, load_task_scene
from vbgs.data.blender import write_blender
from vbgs.data.synthetic import room_scene
from vbgs.data.writers import write_replica


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return write_blender(room_scene(size=32, n_train=16, n_test=3, n_val=2, seed=0),
                         tmp_path_factory.mktemp("doctor") / "room")


def inverted(clean, tmp_path):
    """A copy of the folder whose poses are world-to-camera."""
    out = tmp_path / "w2c"
    shutil.copytree(clean, out)
    for split in ("train", "test", "val"):
        path = out / f"transforms_{split}.json"
        meta = json.loads(path.read_text())
        for f in meta["frames"]:
            f["transform_matrix"] = np.linalg.inv(f["transform_matrix"]).tolist()
        path.write_text(json.dumps(meta))
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


class StopLearner:
    """Stands in for a learner: stops when built, after the scene's checks and warnings."""

    @staticmethod
    def check(task):
        pass

    def __init__(self, task, scene):
        raise ValueError(f"stopped with {len(scene.train)} frames, record {scene.record}")


def test_fit_scene_warns_on_views_that_disagree_before_any_work(clean, tmp_path, capsys,
                                                                monkeypatch):
    """Consistency is a warning (views may differ for reasons the doctor cannot see); the
    scene the learner gets carries where its camera and depth scale came from. (The
    convention cases one by one: tests/experiments/test_bad_input.py.)"""
    monkeypatch.setitem(scene_task.LEARNERS, "vbgs", StopLearner)
    assert main(["fit-scene", "--scene", str(inverted(clean, tmp_path)), "--size", "32",
                 "--components", "300", "--frames", "6", "--depth-scale", "1000"]) == 2
    err = capsys.readouterr().err
    assert "warning: consistency: only" in err and "world-to-camera" in err
    assert "stopped with 6 frames" in err and "'depth_scale_from': '--depth-scale'" in err
    assert "'format': 'blender'" in err


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
