"""``python -m experiments.run tune``: render settings chosen on validation views only."""

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

import experiments.studies.tune as tune_module
from experiments.learners import VbgsLearner
from experiments.provenance import is_stamped_markdown
from experiments.tasks.protocol import evaluate_validation, stream_frames
from experiments.run import main
from experiments.tasks.scene_task import SceneTask, load_task_scene
from experiments.studies.tune import inert_parameters, parse_grid, settings, tune
from vbgs.data.streams import stream_order

TINY = SceneTask(components=150, frames=3, n_test=1, n_val=2, size=16, init="data")
TUNE = ["tune", "--scene", "object", "--components", "150", "--frames", "3", "--size", "16",
        "--val-views", "2"]


def fresh_validation(task, scene):
    """The validation scores of a VBGS learner streamed anew under ``task`` (the slow
    reference a tuned row is held to)."""
    learner = VbgsLearner(task, scene)
    order = stream_order(len(scene.train), task.order, seed=task.seed)
    for _, frame, background in stream_frames(task, scene, order):
        learner.learn(frame, background)
    return evaluate_validation(learner.splats(), scene, background, learner.blur)


def test_parse_grid_types_values_by_the_task_field():
    grid = parse_grid(["splat_scale=0.5,1", "opacity=0.9"], TINY)
    assert grid == {"splat_scale": [0.5, 1.0], "opacity": [0.9]}
    assert all(isinstance(v, float) for v in grid["splat_scale"])
    assert settings(grid) == [{"splat_scale": 0.5, "opacity": 0.9},
                              {"splat_scale": 1.0, "opacity": 0.9}]


def test_model_hyperparameters_are_tuned_as_prior_fields():
    grid = parse_grid(["prior.cov_scale=0.2,0.5", "splat_scale=1"], TINY)
    assert grid == {"prior.cov_scale": [0.2, 0.5], "splat_scale": [1.0]}
    task = tune_module.with_setting(TINY, {"prior.cov_scale": 0.2, "splat_scale": 1.5})
    assert task.prior.cov_scale == 0.2 and task.splat_scale == 1.5
    assert task.prior.cov_strength == TINY.prior.cov_strength  # the other fields kept


def test_every_method_constant_is_reached_by_its_dotted_name():
    """Growth and evidence constants are tuned like the prior's (one stream per value),
    typed by the field, and reach the learner's mapping config."""
    from experiments.learners.vbgs_learner import task_config

    grid = parse_grid(["growth.reach_cells=1.5,3", "growth.levels=2,4",
                       "evidence.pass_sigmas=1,2"], TINY)
    assert grid == {"growth.reach_cells": [1.5, 3.0], "growth.levels": [2, 4],
                    "evidence.pass_sigmas": [1.0, 2.0]}
    task = tune_module.with_setting(TINY, {"growth.reach_cells": 3.0, "growth.levels": 2,
                                           "evidence.pass_sigmas": 1.0})
    config = task_config(task)
    assert (config.growth.reach_cells, config.growth.levels, config.evidence.pass_sigmas) == (
        3.0, 2, 1.0)
    assert config.growth.first_frame_share == TINY.growth.first_frame_share
    with pytest.raises(ValueError, match="growth.reach_cells must be a positive"):
        parse_grid(["growth.reach_cells=0"], TINY)


def test_a_constant_chosen_per_case_reads_none_and_whole_numbers():
    """``growth.denoise_radius`` defaults to None (the sensor's own window): the grid
    reads ``none`` as that and a number as the int the config takes."""
    grid = parse_grid(["growth.denoise_radius=none,1,3"], TINY)
    assert grid == {"growth.denoise_radius": [None, 1, 3]}
    assert isinstance(grid["growth.denoise_radius"][1], int)
    with pytest.raises(ValueError, match="growth.denoise_radius must be an integer"):
        parse_grid(["growth.denoise_radius=1.5"], TINY)


def test_a_whole_number_constant_that_takes_a_word_reads_it():
    """``growth.spent_levels`` takes a number of levels or the word ``ground``: the grid
    reads both, and the map refuses a word it does not take, in its own words."""
    grid = parse_grid(["growth.spent_levels=0,1,ground"], TINY)
    assert grid == {"growth.spent_levels": [0, 1, "ground"]}
    with pytest.raises(ValueError, match='growth.spent_levels must be a whole number'):
        parse_grid(["growth.spent_levels=0,all"], TINY)
    with pytest.raises(ValueError, match="cannot read '1,2.5' as int"):
        parse_grid(["growth.levels=1,2.5"], TINY)
    with pytest.raises(ValueError, match="recolour_reference must be one of"):
        parse_grid(["evidence.recolour_reference=history,2"], TINY)


@pytest.mark.parametrize("spec, message", [
    (["prior.bogus=1"], "'prior.bogus' is not a method constant"),
    (["prior.cov_scale=-1"], "cov_scale must be a positive finite number"),
    (["prior.cov_scale=big"], "cannot read 'big' as float"),
    (["opacity"], "write NAME=V1,V2"),
    (["colour=1,2"], "'colour' is not a task setting"),
    (["components=100,200"], "'components' changes what is learned or scored"),
    (["sensor=exact,kinect"], "'sensor' changes what is learned or scored"),
    (["simulate_sensor=exact,kinect"], "'simulate_sensor' changes what is learned"),
    (["opacity=0.5", "opacity=0.9"], "'opacity' is given twice"),
    (["opacity=high"], "cannot read 'high' as float"),
])
def test_bad_grids_are_refused_with_the_fix(spec, message):
    with pytest.raises(ValueError, match=message):
        parse_grid(spec, TINY)


def test_each_rerender_equals_a_fresh_stream_with_that_setting():
    """Stream once and re-render (the tuning's fast path) == a learner streamed anew with
    the setting in its task (the slow reference)."""
    scene = load_task_scene(TINY)
    grid = {"splat_scale": [0.6, 1.2], "splat_blur": [0.05, 0.3], "opacity": [0.4]}
    rows = tune(TINY, scene, grid)
    assert [r["val_psnr"] for r in rows] == sorted((r["val_psnr"] for r in rows), reverse=True)
    # not the task's own setting
    row = next(r for r in rows if r["splat_scale"] == 1.2 and r["splat_blur"] == 0.05)
    task = replace(TINY, splat_scale=1.2, splat_blur=0.05, opacity=0.4)
    fresh = fresh_validation(task, scene)
    assert row["val_psnr"] == pytest.approx(fresh.psnr, abs=1e-4)
    assert row["val_ssim"] == pytest.approx(fresh.ssim, abs=1e-5)
    assert abs(rows[0]["val_psnr"] - rows[1]["val_psnr"]) > 0.01  # settings change the picture
    by_blur = {r["splat_blur"]: r["val_psnr"] for r in rows if r["splat_scale"] == 1.2}
    assert abs(by_blur[0.05] - by_blur[0.3]) > 0.01  # the pixel filter reaches the render


def test_a_prior_value_equals_a_fresh_stream_under_that_prior():
    """A ``prior.NAME`` grid value relearns the stream: its row equals a learner streamed
    anew with that PriorConfig, and the values give different pictures."""
    scene = load_task_scene(TINY)
    rows = tune(TINY, scene, {"prior.cov_scale": [0.2, 0.5], "splat_scale": [1.2]})
    by_value = {r["prior.cov_scale"]: r["val_psnr"] for r in rows}
    assert abs(by_value[0.2] - by_value[0.5]) > 0.01
    task = replace(TINY, prior=replace(TINY.prior, cov_scale=0.2), splat_scale=1.2)
    fresh = fresh_validation(task, scene)
    assert by_value[0.2] == pytest.approx(fresh.psnr, abs=1e-4)


def test_the_candidate_search_is_learned_once_per_value():
    """``search`` changes which components a point is scored against: each value is a
    stream of its own (not a re-render of one), equal to a learner streamed anew with it."""
    task = replace(TINY, init="stream", components=400)
    scene = load_task_scene(task)
    rows = tune(task, scene, {"search": ["kdtree", "projective"]})
    by_value = {r["search"]: r["val_psnr"] for r in rows}
    assert by_value["kdtree"] != by_value["projective"]
    fresh_task = replace(task, search="projective")
    fresh = fresh_validation(fresh_task, scene)
    assert by_value["projective"] == pytest.approx(fresh.psnr, abs=1e-4)


def test_the_gradient_baseline_is_tuned_static_by_its_dotted_constants():
    """``baseline.NAME`` (the baseline's TrainConfig, densification included) is typed by
    its field; under the static protocol each value's row equals a fresh static run."""
    from experiments.learners import GradientLearner
    from experiments.tasks.protocol import PROGRESS_BLOCK, static_background

    task = replace(TINY, method="gradient", protocol="static", steps=PROGRESS_BLOCK + 5)
    grid = parse_grid(["baseline.depth_weight=0,0.5", "baseline.densify.every=7"], task)
    assert grid == {"baseline.depth_weight": [0.0, 0.5], "baseline.densify.every": [7]}
    scene = load_task_scene(task)
    rows = tune(task, scene, grid)
    by_value = {r["baseline.depth_weight"]: r["val_psnr"] for r in rows}
    assert by_value[0.0] != by_value[0.5]
    fresh_task = tune_module.with_setting(task, {"baseline.depth_weight": 0.5,
                                                 "baseline.densify.every": 7})
    assert fresh_task.baseline.densify.every == 7 and fresh_task.baseline.depth_weight == 0.5
    learner = GradientLearner(fresh_task, scene)
    frames, background = learner.static_frames(scene), static_background(fresh_task, scene)
    learner.train(frames, PROGRESS_BLOCK, background)
    learner.train(frames, 5, background)
    fresh = evaluate_validation(learner.splats(), scene, background, learner.blur)
    assert by_value[0.5] == pytest.approx(fresh.psnr, abs=1e-4)


def test_a_parameter_that_changes_no_score_is_named():
    grid = {"splat_scale": [0.5, 1.0], "opacity": [0.3, 0.9]}
    rows = [{"splat_scale": s, "opacity": o, "val_psnr": 20.0 + s}  # opacity: no effect
            for s in grid["splat_scale"] for o in grid["opacity"]]
    assert inert_parameters(rows, grid) == ["opacity"]
    rows[0]["val_psnr"] = 5.0
    assert inert_parameters(rows, grid) == []


def test_tuning_never_renders_a_test_view(monkeypatch):
    scene = load_task_scene(TINY)
    test_ids = {id(f) for f in scene.test}
    seen = []
    real = tune_module.evaluate_validation

    def spy(splats, scene_, background, blur):
        seen.extend(id(f) for f in scene_.val)
        return real(splats, scene_, background, blur)

    monkeypatch.setattr(tune_module, "evaluate_validation", spy)
    tune(TINY, scene, {"splat_scale": [0.7]})
    assert seen and not test_ids & set(seen)
    with pytest.raises(ValueError, match="no validation views"):
        evaluate_validation(None, scene._replace(val=[]), np.ones(3))


def test_tune_command_writes_its_table_headed_by_the_command(tmp_path, capsys):
    out = tmp_path / "tuning"
    argv = [*TUNE, "--grid", "splat_scale=0.7,1.0", "opacity=0.5", "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "best: splat_scale=" in printed
    csv, md = out / "object.csv", out / "object.md"
    header = csv.read_text().splitlines()[0]
    assert header.startswith("# command: python -m experiments.run tune --scene object")
    assert "--grid splat_scale=0.7,1.0 opacity=0.5" in header
    table = pd.read_csv(csv, comment="#")
    assert list(table.columns) == ["splat_scale", "opacity", "val_psnr", "val_ssim",
                                   "val_depth_l1"]
    assert sorted(table["splat_scale"]) == [0.7, 1.0] and (table["opacity"] == 0.5).all()
    assert table["val_psnr"].is_monotonic_decreasing and table["val_psnr"].gt(8).all()
    assert "Command: `python -m experiments.run tune" in md.read_text()
    assert is_stamped_markdown(md.read_text())


@pytest.mark.parametrize("extra, message", [
    (["--grid", "frames=2,3"], "'frames' changes what is learned or scored"),
    (["--val-views", "0"], "--val-views must be at least 1"),
])
def test_tune_refuses_bad_input_before_any_work(extra, message, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(tune_module, "tune", lambda *a, **k: pytest.fail("tuning started"))
    assert main([*TUNE, *extra, "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert not (tmp_path / "t").exists()


def test_colour_rule_is_gathered_while_streaming_and_each_rule_equals_a_fresh_stream(
        monkeypatch):
    """The colour least squares is gathered while the stream is learned (whatever the
    task's own rule), so both colour rules are tuned from one stream; each row equals a
    learner streamed anew under that rule."""
    scene = load_task_scene(TINY)
    base = replace(TINY, colour_rule="posterior")
    rows = tune(base, scene, {"colour_rule": ["fit", "posterior"]})
    for row in rows:
        fresh = fresh_validation(replace(TINY, colour_rule=row["colour_rule"]), scene)
        assert row["val_psnr"] == pytest.approx(fresh.psnr, abs=1e-4)
    assert abs(rows[0]["val_psnr"] - rows[1]["val_psnr"]) > 0.01  # the rule changes the picture


def test_several_scenes_get_their_tables_and_a_mean_that_picks_one_setting(tmp_path, capsys):
    out = tmp_path / "tuning"
    argv = ["tune", "--scene", "object", "room", "--components", "150", "--frames", "3",
            "--size", "16", "--val-views", "2", "--grid", "splat_scale=0.7,1.0",
            "prior.cov_scale=0.3,0.5", "--out", str(out)]
    assert main(argv) == 0
    assert "best: splat_scale=" in capsys.readouterr().out
    scenes = {n: pd.read_csv(out / f"{n}.csv", comment="#") for n in ("object", "room")}
    mean = pd.read_csv(out / "mean.csv", comment="#")
    assert len(mean) == 4 and mean["val_psnr"].is_monotonic_decreasing
    for _, row in mean.iterrows():
        own = [t[(t["splat_scale"] == row["splat_scale"])
                 & (t["prior.cov_scale"] == row["prior.cov_scale"])].iloc[0] for t in scenes.values()]
        assert row["object_psnr"] == pytest.approx(own[0]["val_psnr"])
        assert row["room_psnr"] == pytest.approx(own[1]["val_psnr"])
        assert row["val_psnr"] == pytest.approx((own[0]["val_psnr"] + own[1]["val_psnr"]) / 2)
        assert row["val_ssim"] == pytest.approx((own[0]["val_ssim"] + own[1]["val_ssim"]) / 2)
    assert "--scene object room" in (out / "mean.md").read_text()


def test_tune_learns_under_a_simulated_sensor_and_names_it_in_the_command(tmp_path, capsys):
    """The depth preprocessing of a measured sensor is tuned on its own noisy frames: the
    two radii learn different maps, and the command in the table says which sensor."""
    out = tmp_path / "tuning"
    argv = [*TUNE, "--simulate-sensor", "kinect", "--sensor", "kinect",
            "--grid", "growth.denoise_radius=0,2", "--out", str(out)]
    assert main(argv) == 0
    capsys.readouterr()
    header = (out / "object.csv").read_text().splitlines()[0]
    assert "--simulate-sensor kinect --sensor kinect --grid growth.denoise_radius=0,2" in header
    table = pd.read_csv(out / "object.csv", comment="#")
    assert sorted(table["growth.denoise_radius"]) == [0, 2]
    assert table["val_psnr"].nunique() == 2
    # the stream reads the simulated sensor's depth, not the scene's exact depth
    scores = {}
    for simulated in ("exact", "kinect"):
        assert main([*TUNE, "--simulate-sensor", simulated, "--grid", "splat_scale=1.0",
                     "--out", str(tmp_path / simulated)]) == 0
        scores[simulated] = pd.read_csv(tmp_path / simulated / "object.csv",
                                        comment="#")["val_depth_l1"][0]
    assert scores["kinect"] != scores["exact"]
