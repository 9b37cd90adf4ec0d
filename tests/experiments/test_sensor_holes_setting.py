"""The simulated sensor's holes as a task setting (``sensor_holes``, ``--sensor-holes``):
on the training frames only, the realised share in the depth report, refused for a
sensor without holes and when malformed, dropped by a sweep where it cannot apply."""

import numpy as np
import pytest

import experiments.tasks.scene_task as scene_task
from experiments.run import main
from experiments.tasks.scene_task import SceneTask, prepare_scene
from experiments.sweep.cells import expand
from experiments.sweep.config import ConfigError, parse_config

TASK = dict(scene="object", components=600, frames=4, n_test=2, size=32)


def test_the_holes_change_the_training_frames_only():
    exact, _ = prepare_scene(SceneTask(**TASK))
    none, quiet = prepare_scene(SceneTask(**TASK, simulate_sensor="kinect", sensor_level=0.0,
                                          sensor_holes="none"))
    holed, report = prepare_scene(SceneTask(**TASK, simulate_sensor="kinect", sensor_level=0.0,
                                            sensor_holes="random:0.1"))
    # level 0 without holes is the exact depth; random:0.1 empties about 10 % of it
    assert all(np.array_equal(a.depth, b.depth) for a, b in zip(none.train, exact.train,
                                                                 strict=True))
    assert quiet["depth_sensor_holes"] == 0.0 and 0.07 < report["depth_sensor_holes"] < 0.13
    assert report["depth_sensor_abs_error"] == 0.0
    assert all(np.array_equal(a.depth, b.depth) for a, b in zip(holed.test, exact.test,
                                                                 strict=True))
    _, own = prepare_scene(SceneTask(**TASK, simulate_sensor="kinect", sensor_level=0.0))
    _, physical = prepare_scene(SceneTask(**TASK, simulate_sensor="kinect", sensor_level=0.0,
                                          sensor_holes="physical"))
    # at level 0 the sensor's own holes are its physical ones (no random dropouts)
    assert own["depth_sensor_holes"] == physical["depth_sensor_holes"] > 0.2


@pytest.mark.parametrize("argv, message", [
    (["--sensor-holes", "random:0.05"],
     "sensor_holes 'random:0.05' sets the holes of a simulated sensor, but simulate_sensor "
     "'exact' makes none"),
    (["--simulate-sensor", "mono", "--sensor-holes", "none"], "'mono' makes none"),
    (["--simulate-sensor", "kinect", "--sensor-holes", "random:5"],
     "sensor_holes: holes 'random:5': the random dropout RATE must be a probability"),
    (["--simulate-sensor", "kinect", "--sensor-holes", "edges"],
     "sensor_holes: unknown holes 'edges': use one of sensor, none, physical"),
])
def test_bad_holes_are_refused_in_one_line(argv, message, monkeypatch, capsys):
    def fit(*a, **k):
        raise AssertionError("the fit started before the input was checked")

    monkeypatch.setattr(scene_task, "run_scene", fit)
    assert main(["fit-scene", "--scene", "object", "--size", "32", "--frames", "4",
                 "--components", "600", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err


def _plan(grid):
    return expand(parse_config({"name": "t", "fixed": {"size": 16, "frames": 3},
                                "grid": [{"task": "scene", "dataset": "object", **grid}]}))


def test_a_sweep_varies_the_holes_of_a_sensor_that_makes_them():
    plan = _plan({"simulate_sensor": ["exact", "kinect"],
                  "sensor_holes": ["none", "random:0.05", "physical"]})
    cells = [c.as_dict() for c in plan.cells]
    # exact makes no holes: one exact cell, three kinect cells
    assert len(cells) == 4
    assert sorted(c.get("sensor_holes", "-") for c in cells) == [
        "-", "none", "physical", "random:0.05"]
    with pytest.raises(ConfigError, match="sensor_holes: unknown holes 'edges'"):
        _plan({"simulate_sensor": "kinect", "sensor_holes": ["edges"]})
