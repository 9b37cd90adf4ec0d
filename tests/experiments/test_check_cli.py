"""`python -m experiments.run check` end to end on a Blender folder written from the
synthetic room; --frames N and the test views it scores. (Each corruption and the cause
the doctor names, and fit-scene's warning: tests/experiments/test_bad_input.py.)"""

import json

import pytest

from experiments.run import main
from experiments.tasks.scene_task import SceneTask, load_task_scene
from vbgs.data.blender import write_blender
from vbgs.data.synthetic import room_scene
from vbgs.data.writers import write_replica


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return write_blender(room_scene(size=32, n_train=16, n_test=3, n_val=2, seed=0),
                         tmp_path_factory.mktemp("doctor") / "room")


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
