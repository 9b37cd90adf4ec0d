"""The "walk" scene (an open trajectory) through the commands: fit-scene, tune's scene
loading and a sweep cell."""

import json

import numpy as np

from experiments.run import main
from experiments.tasks.scene_task import SceneTask, load_task_scene
from experiments.sweep.cells import expand
from experiments.sweep.config import load_config
from experiments.sweep.tasks import TASKS, build_task
from vbgs.data.synthetic import WALK_SKY

TINY = ["--scene", "walk", "--components", "600", "--frames", "6", "--test-views", "2",
        "--size", "32"]


def test_fit_scene_on_the_walk(capsys):
    # in-process (test_fit_scene_cli runs fit-scene as a real process): the walk's learner
    # at these shapes is compiled already by test_continual's run
    assert main(["fit-scene", *TINY, "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["scene"] == "walk" and r["frames"] == 6 and r["n_test"] == 2
    for key in ("psnr", "ssim", "depth_l1", "points_unlearned", "early_psnr_when_seen",
                "early_psnr_at_end"):
        assert np.isfinite(r[key]), key
    # measured 17.91 dB (seed 0); the sky colour alone scores 8.1 dB on these two views
    assert r["psnr"] > 17.0
    assert 0 < r["components_used"] <= 600 and 0.0 <= r["points_unlearned"] <= 1.0
    # the background is estimated from the pixels without depth: the sky
    np.testing.assert_allclose(r["background_rgb"], WALK_SKY, atol=0.02)


def test_task_scene_loads_the_walk_with_validation_views():
    """What fit-scene, tune (validation views) and a sweep cell load for scene = "walk"."""
    scene = load_task_scene(SceneTask(scene="walk", frames=3, n_test=2, n_val=2, size=16))
    assert scene.name == "walk" and scene.background == WALK_SKY
    assert (len(scene.train), len(scene.test), len(scene.val)) == (3, 2, 2)
    # the longer walk is a built-in name too, its frames at the walk's step
    long = load_task_scene(SceneTask(scene="walk-long", frames=3, n_test=2, n_val=2, size=16))
    assert long.name == "walk-long" and long.background == WALK_SKY
    assert "walk-long" in TASKS["scene"].dataset_names()


def test_sweep_accepts_a_walk_cell(tmp_path):
    """A quick-sweep-style scene grid on the walk parses, expands and builds its task."""
    assert "walk" in TASKS["scene"].dataset_names()  # a built-in name, not a path
    path = tmp_path / "walk.toml"
    path.write_text("""
name = "walk"
[[grid]]
task = "scene"
dataset = "walk"
size = 48
frames = 20
n_test = 4
init = ["stream", "data"]
components = 3000
order = "sequential"
assign = ["prior", "posterior"]
seed = [0, 1]
""")
    plan = expand(load_config(path))
    assert not plan.skipped and len(plan.cells) == 8
    cells = [c.as_dict() for c in plan.cells]
    assert {c["dataset"] for c in cells} == {"walk"}
    task = build_task(cells[0])
    assert isinstance(task, SceneTask) and task.scene == "walk" and task.frames == 20
