"""``python -m experiments.run front``: every method's row, the CSV's columns, the
Pareto front and the plot, on a tiny scene."""

import json

import numpy as np
import pandas as pd
import pytest

from experiments.provenance import is_stamped_markdown
from experiments.studies.front import COLUMNS, mark_front, parse_counts, pareto
from experiments.run import main


def test_pareto_keeps_the_rows_nothing_beats():
    cost = np.array([1.0, 2.0, 3.0, 2.0, 5.0])
    score = np.array([10.0, 12.0, 11.0, 12.0, 13.0])
    # row 2 is slower and worse than row 1; rows 1 and 3 tie (neither dominates)
    assert pareto(cost, score).tolist() == [True, True, False, True, True]


def test_a_polish_timed_under_its_vbgs_run_cannot_push_vbgs_off_the_front(capsys):
    """The polish contains the VBGS run of its component count: timed shorter (noise), it
    is placed at that run's time and said on stderr; a row without a PSNR is on no front."""
    rows = [{"method": "vbgs", "components": 300, "steps": 0, "wall_seconds": 2.0,
             "psnr": 18.0},
            {"method": "vbgs-polish", "components": 300, "steps": 50, "wall_seconds": 1.9,
             "psnr": 19.0},
            {"method": "gradient", "components": 300, "steps": 50, "wall_seconds": 0.5,
             "psnr": float("nan")}]
    marked = mark_front(rows)
    assert [r["on_front"] for r in marked] == [True, True, False]
    assert marked[1]["wall_seconds"] == 1.9  # the row keeps its measured time
    err = capsys.readouterr().err
    assert "timed at 1.90 s, under the 2.00 s of the VBGS run it contains" in err


def test_step_lists_are_refused_in_words():
    assert parse_counts("10, 20", "--steps") == (10, 20)
    with pytest.raises(ValueError, match="positive integers"):
        parse_counts("10,0", "--polish-steps")


@pytest.mark.slow  # 31 s of compiling five learners; test_static_front_on_a_tiny_scene is the default run's
def test_front_on_a_tiny_scene(tmp_path, capsys):
    out = tmp_path / "front"
    code = main(["front", "--scene", "object", "--size", "16", "--components", "100",
                 "--frames", "3", "--test-views", "1", "--polish-steps", "2",
                 "--gradient-steps", "3", "--replays", "fifo:2", "--steps-per-frame", "1",
                 "--out", str(out), "--json"])
    assert code == 0
    captured = capsys.readouterr()
    assert "front runs 0/5" in captured.err  # progress on stderr (its first line)
    files = json.loads(captured.out.strip().splitlines()[-1])["files"]
    assert str(out / "object.png") in files and (out / "object.png").stat().st_size > 10_000
    assert is_stamped_markdown((out / "object.md").read_text())
    table = pd.read_csv(out / "object.csv")
    assert set(COLUMNS) | {"on_front"} <= set(table.columns)
    assert sorted(zip(table.method, table.protocol, table.replay, strict=True)) == sorted([
        ("vbgs", "continual", "none"), ("vbgs-polish", "static", "none"),
        ("gradient", "static", "none"), ("gradient", "continual", "fifo:2"),
        ("vbgs-polish", "continual", "fifo:2")])
    assert table.loc[table.protocol == "static", "steps"].tolist() == [2, 3]
    frame_bytes = 16 * 16 * 4 * 4  # rgb + depth, float32
    assert (table.loc[table.replay == "fifo:2", "replay_bytes"] == 2 * frame_bytes).all()
    assert (table.wall_seconds > 0).all() and table.psnr.between(5, 60).all()
    front = table[table.on_front]
    assert len(front) >= 1
    for _, row in front.iterrows():  # nothing at least as fast is better
        rivals = table[(table.wall_seconds <= row.wall_seconds) & (table.psnr > row.psnr)]
        assert rivals.empty
    assert not table[~table.on_front].empty or len(table) == len(front)


def test_front_refuses_several_scene_component_counts(capsys):
    code = main(["front", "--scene", "object", "--components", "100,200", "--json"])
    assert code == 2
    assert "one count" in capsys.readouterr().err


def test_image_front_times_warm_fits(tmp_path):
    out = tmp_path / "img"
    assert main(["front", "--image", "astronaut", "--size", "16", "--components", "20",
                 "--gradient-steps", "5", "--iters", "2", "--out", str(out)]) == 0
    table = pd.read_csv(out / "astronaut.csv")
    assert table.method.tolist() == ["vbgs", "gradient"]
    assert table.steps.tolist() == [2, 5] and (table.protocol == "image").all()
    assert (table.compile_seconds >= 0).all() and (out / "astronaut.png").exists()


class TickClock:
    """A clock that moves one second at each reading: a checkpoint's bookkeeping (its
    training counted, earlier checkpoints' scoring left out) without wall-clock noise (the
    real clock failed this test once, a 30-step checkpoint's render stretched by 50 ms on
    a loaded machine)."""

    def __init__(self):
        self.now = 0.0

    def perf_counter(self) -> float:
        self.now += 1.0
        return self.now


def test_an_image_checkpoint_is_the_fit_of_its_length(monkeypatch):
    """The image front scores one gradient fit at several step counts (per-step schedule;
    candidate refreshes every REFRESH_EVERY steps from the start)."""
    from experiments.tasks import image_task
    from experiments.tasks.image_task import ImageTask, gradient_image_path, run_gradient_image

    task = ImageTask(image="astronaut", size=16, components=20, method="gradient", steps=40)
    alone = run_gradient_image(task, steps=30)  # compiles (a checkpoint's render is timed)
    monkeypatch.setattr(image_task, "time", TickClock())
    path = {r["steps"]: r for r in gradient_image_path(task, (30, 40))}
    np.testing.assert_array_equal(path[30]["images"]["render"], alone["images"]["render"])
    assert path[30]["loss"] == alone["loss"] and len(path[40]["loss"]) == 40
    assert path[30]["seconds"] < path[40]["seconds"]


TINY_SCENE = dict(scene="object", size=16, components=100, frames=3, n_test=1, n_val=0)


@pytest.mark.parametrize("method", ["vbgs-polish", "gradient"])
def test_a_checkpoint_is_the_run_of_its_length(method):
    """The front scores one static run at several step counts: the learners' schedules
    and draws are per step, so 3 steps of a 6-step run are a 3-step run (the gradient's
    relocation every 2 steps included)."""
    from dataclasses import replace

    from experiments.tasks.scene_task import SceneTask, run_scene, run_scene_checkpoints
    from vbgs.baseline.densify import DensifyConfig

    # each method's init as the front runs it (experiments.studies.front.scene_runs: the polish
    # streams, the gradient starts from the data), so the compiled learners are the ones
    # test_static_front_on_a_tiny_scene runs
    init = {"init": "data"} if method == "gradient" else {}
    task = SceneTask(**TINY_SCENE, method=method, protocol="static", **init)
    task = replace(task, baseline=replace(task.baseline, densify=DensifyConfig(every=2)))
    path = dict(run_scene_checkpoints(replace(task, steps=6), (3, 6)))
    alone = run_scene(replace(task, steps=3))
    assert [path[n].details["steps_total"] for n in (3, 6)] == [3, 6]
    assert path[3].settings["steps"] == 3
    np.testing.assert_array_equal(np.asarray(path[3].images["render"]),
                                  np.asarray(alone.images["render"]))
    assert path[3].psnr == alone.psnr and path[6].psnr != alone.psnr
    assert 0 < path[3].seconds < path[6].seconds  # cumulative training seconds


def test_static_front_on_a_tiny_scene(tmp_path, capsys):
    """The static rows: each method's one run scored at every step count."""
    out = tmp_path / "front"
    assert main(["front", "--scene", "object", "--size", "16", "--components", "100",
                 "--frames", "3", "--test-views", "1", "--polish-steps", "1,2",
                 "--gradient-steps", "1,3", "--replays", "", "--out", str(out)]) == 0
    assert "front runs 0/3" in capsys.readouterr().err  # progress (its first line)
    table = pd.read_csv(out / "object.csv")
    assert list(zip(table.method, table.steps, strict=True)) == [
        ("vbgs", 0), ("vbgs-polish", 1), ("vbgs-polish", 2), ("gradient", 1), ("gradient", 3)]
    for method in ("vbgs-polish", "gradient"):  # cumulative seconds along one run
        assert table.loc[table.method == method, "wall_seconds"].is_monotonic_increasing
    assert (out / "object.png").exists() and table.on_front.any()
    (out / "object.png").unlink()  # drawn again from the CSV alone
    assert main(["front", "--replot", str(out / "object.csv")]) == 0
    assert (out / "object.png").stat().st_size > 10_000
