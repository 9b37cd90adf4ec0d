"""``fit-scene --simulate-sensor``: only the training frames' depth is corrupted (test
and validation views bit-identical to an exact run), seeded per frame, the sensor
reported in the JSON; bad values refused in one line; a sweep varies the sensor for
both methods."""

import json

import numpy as np
import pytest

import experiments.tasks.scene_task as scene_task
from experiments.run import main
from experiments.tasks.scene_task import SceneTask, prepare_scene
from experiments.sweep.cells import expand
from experiments.sweep.config import ConfigError, parse_config
from experiments.sweep.tasks import build_task

TINY = ["--scene", "object", "--components", "600", "--frames", "6", "--test-views", "2",
        "--size", "32", "--json"]
TASK = dict(scene="object", components=600, frames=6, n_test=2, size=32)


def _same_frames(a, b) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x.rgb, y.rgb) and np.array_equal(x.depth, y.depth)
        and np.array_equal(np.asarray(x.camera.pose), np.asarray(y.camera.pose))
        for x, y in zip(a, b, strict=True))


def test_fit_scene_kinect_corrupts_only_the_training_depth(monkeypatch, capsys):
    seen = {}

    def recording(task):
        seen["task"] = task
        seen["scene"], seen["report"] = prepare_scene(task)
        return seen["scene"], seen["report"]

    monkeypatch.setattr(scene_task, "prepare_scene", recording)
    assert main(["fit-scene", *TINY, "--simulate-sensor", "kinect"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    exact, report = prepare_scene(SceneTask(**TASK))
    assert report["depth_sensor"] == "exact" and report["depth_sensor_holes"] == 0.0
    corrupted = seen["scene"]
    assert _same_frames(corrupted.test, exact.test) and _same_frames(corrupted.val, exact.val)
    assert len(corrupted.test) == 2 and len(corrupted.val) == 4
    for noisy, true in zip(corrupted.train, exact.train, strict=True):
        assert np.array_equal(noisy.rgb, true.rgb)  # colour untouched
        assert not np.array_equal(noisy.depth, true.depth)
        assert ((noisy.depth == 0) | (true.depth > 0)).all()  # no depth invented
    # the record: measured 39.2 % of the pixels with depth became holes at 32 px (the
    # silhouettes are a large share there), median |error| 14.5 mm at 3-5 m; held-out
    # PSNR 17.66 dB against 19.85 dB exact (the learner does not model the noise yet)
    assert (result["simulate_sensor"], result["sensor_level"]) == ("kinect", 1.0)
    assert (result["depth_source"], result["depth_sensor"]) == ("simulated", "kinect")
    assert result["depth_sensor_level"] == 1.0
    assert 0.3 < result["depth_sensor_holes"] < 0.5
    assert 0.008 < result["depth_sensor_abs_error"] < 0.025
    assert 16.5 < result["psnr"] < 19.85 and 0 < result["components_used"] <= 600


def test_seeded_per_frame_and_per_task_seed():
    kinect = SceneTask(**TASK, simulate_sensor="kinect")
    a, report = prepare_scene(kinect)
    b, again = prepare_scene(kinect)
    assert _same_frames(a.train, b.train) and report == again
    c, _ = prepare_scene(SceneTask(**TASK, simulate_sensor="kinect", seed=1))
    assert not np.array_equal(a.train[0].depth, c.train[0].depth)
    # each frame draws its own noise: the kinect's errors are white, so two frames'
    # error maps on the pixels both kept are uncorrelated
    first, second = (f.depth.astype(np.float64) - t.depth
                     for f, t in zip(a.train[:2], prepare_scene(SceneTask(**TASK))[0].train[:2],
                                     strict=True))
    both = (a.train[0].depth > 0) & (a.train[1].depth > 0)
    assert abs(np.corrcoef(first[both], second[both])[0, 1]) < 0.3


def test_mono_and_level_zero_reports():
    _, mono = prepare_scene(SceneTask(**TASK, simulate_sensor="mono"))
    # mono has no holes; its median error is a few per cent of 3-5 m
    assert mono["depth_sensor_holes"] == 0.0 and 0.02 < mono["depth_sensor_abs_error"] < 0.3
    scene, still = prepare_scene(SceneTask(**TASK, simulate_sensor="realsense",
                                           sensor_level=0.0))
    assert still["depth_sensor_abs_error"] == 0.0 and 0.2 < still["depth_sensor_holes"] < 0.6
    assert all((f.depth > 0).all() for f in
               prepare_scene(SceneTask(**TASK, simulate_sensor="mono"))[0].train)


@pytest.mark.parametrize("argv, message", [
    (["--simulate-sensor", "lidar"],
     "unknown simulate_sensor 'lidar': use one of exact, kinect, realsense, mono"),
    (["--simulate-sensor", "kinect", "--sensor-level", "-1"],
     "sensor_level must be a finite number >= 0"),
    (["--sensor-level", "nan"], "sensor_level must be a finite number >= 0"),
    (["--simulate-sensor", "mono", "--depth-model", "m.onnx"],
     "simulate_sensor 'mono' and depth_model both replace the training depth"),
])
def test_bad_values_are_refused_in_one_line(argv, message, monkeypatch, capsys):
    def fit(*a, **k):
        raise AssertionError("the fit started before the input was checked")

    monkeypatch.setattr(scene_task, "run_scene", fit)
    assert main(["fit-scene", *TINY, *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err


# ------------------------------------------------------------------------- sweep


def _plan(grid, **fixed):
    return expand(parse_config({"name": "t", "fixed": {"size": 16, "frames": 3, **fixed},
                                "grid": [{"task": "scene", "dataset": "object", **grid}]}))


def test_a_sweep_varies_the_sensor_for_both_methods():
    plan = _plan({"method": ["vbgs", "gradient"], "simulate_sensor": ["exact", "kinect"],
                  "sensor_level": [1.0, 2]})
    cells = [c.as_dict() for c in plan.cells]
    # exact has no level to vary: 2 methods x (exact + kinect at 2 levels)
    assert len(cells) == 6 and not [s for s in plan.skipped if "skip" in s.reason]
    gradient = [c for c in cells if c["method"] == "gradient"]
    assert {c["simulate_sensor"] for c in gradient} == {"exact", "kinect"}
    assert all("sensor_level" not in c for c in cells if c["simulate_sensor"] == "exact")
    task = build_task(next(c for c in gradient if c.get("sensor_level") == 2))
    assert (task.method, task.simulate_sensor, task.sensor_level) == ("gradient", "kinect", 2)


def test_a_sweep_refuses_bad_sensor_values(tmp_path):
    with pytest.raises(ConfigError, match="simulate_sensor: must be one of exact, kinect"):
        _plan({"simulate_sensor": ["sonar"]})
    with pytest.raises(ConfigError, match="sensor_level: must be a finite number >= 0"):
        _plan({"sensor_level": [-1.0]})
    model = tmp_path / "m.onnx"
    model.write_bytes(b"")
    plan = _plan({"simulate_sensor": ["exact", "mono"], "depth_model": ["sensor", str(model)]})
    assert len(plan.cells) == 3 and len(plan.skipped) == 1
    assert "the simulated sensor corrupts" in plan.skipped[0].reason


def test_a_measured_folder_scores_as_the_simulation(tmp_path, capsys):
    """The Kinect's training frames written as a Blender folder (16-bit mm depth PNGs,
    8-bit colour) and learned with --sensor kinect score as the in-memory simulation
    (measured at 64 px / 5000 components: 20.70 against 20.69 dB; here at 32 px)."""
    from vbgs.data.blender import write_blender

    size = ["--components", "600", "--frames", "6", "--test-views", "2", "--size", "32"]
    task = SceneTask(scene="object", components=600, frames=6, n_test=2, size=32)
    noisy, _ = scene_task.simulate_training_depth(scene_task.load_task_scene(task), "kinect",
                                                  1.0, seed=task.seed)
    folder = write_blender(noisy, tmp_path / "kinect")
    scores = []
    for scene in (["--scene", "object", "--simulate-sensor", "kinect"],
                  ["--scene", str(folder)]):
        assert main(["fit-scene", *scene, "--sensor", "kinect", *size, "--json"]) == 0
        scores.append(json.loads(capsys.readouterr().out.strip().splitlines()[-1])["psnr"])
    assert scores[1] == pytest.approx(scores[0], abs=0.2)
    assert scores[0] > 19.0  # measured 19.56 dB (the depth averaged over its surfaces)
