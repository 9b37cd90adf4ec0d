"""Sweep configs: parsing, refusals naming the key, and the validity rules."""

from pathlib import Path

import pytest

from experiments.run import main
from experiments.sweep.cells import cell_key, expand
from experiments.sweep.config import ConfigError, load_config, parse_config

CONFIGS = Path(__file__).resolve().parents[2] / "experiments" / "configs"


def _config(**grid):
    return {"name": "t", "fixed": {"size": 16, "iters": 2},
            "grid": [{"task": "image", "dataset": ["astronaut"], "components": [20], **grid}]}


def test_quick_config_has_one_cell_of_each_kind():
    """The first command stays minutes long: one cell of each kind a user should see (both
    tasks, both methods, the three stream orders, both assignment modes, the three
    initialisations, a replay buffer, the three synthetic scenes), one seed."""
    config = load_config(CONFIGS / "quick.toml")
    assert config.name == "quick"
    plan = expand(config)
    cells = [c.as_dict() for c in plan.cells]
    assert not plan.skipped and len(cells) <= 16
    values = {k: {c[k] for c in cells if k in c} for k in ("task", "init", "order", "assign",
                                                          "seed", "dataset", "replay")}
    assert values["task"] == {"image", "scene"}
    assert {c.get("method", "vbgs") for c in cells} == {"vbgs", "gradient"}
    assert values["init"] == {"stream", "random", "data"}
    assert values["order"] == {"sequential", "shuffled", "reversed"}
    assert values["assign"] == {"prior", "posterior"} and values["seed"] == {0}
    assert {"object", "room", "walk", "astronaut"} <= values["dataset"]
    assert values["replay"] - {"none"}
    assert {c["stream"] for c in cells if c["task"] == "image"} == {"none", "patches"}
    # the batch fits and the gradient baseline: splats far fewer than pixels (>= 8 a splat)
    batch = [c for c in cells if c["task"] == "image" and c.get("stream") == "none"]
    assert batch and all(c["size"] ** 2 >= 8 * c["components"] for c in batch)


def test_ablations_config_parses_and_expands():
    """The long grid: both tasks, both methods, two component counts, every init, the
    three stream orders, both assignment modes, two seeds."""
    config = load_config(CONFIGS / "ablations.toml")
    assert config.name == "ablations"
    plan = expand(config)
    cells = [c.as_dict() for c in plan.cells]
    assert not plan.skipped
    values = {k: {c[k] for c in cells if k in c} for k in ("task", "init", "components",
                                                          "order", "assign", "seed", "dataset")}
    assert values["task"] == {"image", "scene"}
    assert {c.get("method", "vbgs") for c in cells} == {"vbgs", "gradient"}
    assert values["init"] == {"stream", "random", "data"} and len(values["components"]) >= 2
    assert values["order"] == {"sequential", "shuffled", "reversed"}
    assert values["assign"] == {"prior", "posterior"} and values["seed"] == {0, 1}
    assert len(values["dataset"]) >= 3
    assert all(c["stream"] == "patches" for c in cells if c["task"] == "image" and "order" in c)
    batch = [c for c in cells if c["task"] == "image" and c.get("stream") == "none"]
    assert batch and all(c["size"] ** 2 >= 8 * c["components"] for c in batch)


def test_paper_config_parses():
    plan = expand(load_config(CONFIGS / "paper.toml"))
    tasks = {c.as_dict()["task"] for c in plan.cells}
    assert tasks == {"image", "scene"}
    assert not any(c.as_dict().get("method") == "vbgs"
                   and c.as_dict().get("replay", "none") != "none" for c in plan.cells)


@pytest.mark.parametrize(
    "grid, message",
    [
        ({"compnents": [20]}, "grid[0].compnents: unknown key 'compnents' (did you mean "
                              "'components'?)"),
        ({"components": [20, -5]}, "grid[0].components: must be a positive integer, got -5"),
        ({"components": [0]}, "grid[0].components: must be a positive integer, got 0"),
        ({"components": ["500"]}, "grid[0].components: must be an integer (without quotes), "
                                  "\"auto\" or \"auto:MAX\" (MAX a positive integer), got '500'"),
        ({"components": ["auto:0"]}, "(MAX a positive integer), got 'auto:0'"),
        ({"components": [True]}, "grid[0].components: must be an integer or a string, got True"),
        ({"init": ["zeros"]}, "grid[0].init: must be one of stream, data, random, got 'zeros'"),
        ({"order": "backwards"}, "grid[0].order: must be one of sequential"),
        ({"dataset": ["/no/such/photo.png"]}, "grid[0].dataset: '/no/such/photo.png' is "
                                              "neither a built-in dataset"),
        ({"task": ["video"]}, "grid[0].task: must be one of image, scene, got 'video'"),
        ({"replay": ["fifo:0"]}, "grid[0].replay: replay 'fifo:0' needs a size: write fifo:K"),
        ({"replay": ["reservoir"]}, "grid[0].replay: replay 'reservoir' needs a size"),
        ({"replay": ["full:3"]}, "grid[0].replay: replay 'full' takes no size"),
        ({"replay": ["lifo:3"]}, "grid[0].replay: unknown replay 'lifo:3'"),
        ({"depth_model": ["model.pt"]}, "grid[0].depth_model: must be \"sensor\" or the path"),
        ({"seed": []}, "grid[0].seed: an empty list gives no cells"),
        ({"seed": [0, 0]}, "grid[0].seed: repeats a value"),
        ({"seed": [[0, 1]]}, "grid[0].seed: must be a value or a flat list"),
        ({"splat_scale": ["big"]}, "grid[0].splat_scale: must be a positive number or "
                                   "\"auto\", got 'big'"),
        ({"splat_scale": [0.0]}, "grid[0].splat_scale: must be a positive number or "
                                 "\"auto\", got 0.0"),
    ],
)
def test_bad_values_name_the_key(grid, message):
    with pytest.raises(ConfigError) as err:
        parse_config(_config(**grid), "bad.toml")
    assert message in str(err.value)
    assert str(err.value).startswith("bad.toml: ")


@pytest.mark.parametrize(
    "doc, message",
    [
        ({"grid": [{"task": "image", "dataset": "astronaut"}]}, "name: must be a non-empty"),
        ({"name": "t", "grids": []}, "unknown top-level key 'grids'"),
        ({"name": "t"}, "grid: give at least one [[grid]] table"),
        ({"name": "t", "fixed": {"size": [16]}, "grid": [{"task": "image",
                                                          "dataset": "astronaut"}]},
         "fixed.size: [fixed] takes single values"),
        ({"name": "t", "fixed": {"size": -1}, "grid": [{"task": "image",
                                                        "dataset": "astronaut"}]},
         "fixed.size: size -1: the side must be at least 1 pixel"),
        ({"name": "t", "fixed": {"size": "640x"}, "grid": [{"task": "scene",
                                                            "dataset": "room"}]},
         "fixed.size: size '640x' is not a size"),
        ({"name": "t", "grid": [{"dataset": "astronaut"}]}, "grid[0]: missing key 'task'"),
    ],
)
def test_bad_structure(doc, message):
    with pytest.raises(ConfigError, match=None) as err:
        parse_config(doc, "bad.toml")
    assert message in str(err.value)


def test_bad_config_is_refused_before_any_cell_runs(tmp_path, capsys):
    config = tmp_path / "bad.toml"
    config.write_text('name = "bad"\n[[grid]]\ntask = "image"\ndataset = "astronaut"\n'
                      'size = 16\ncomponents = [20, -3]\n')
    out = tmp_path / "results"
    assert main(["sweep", "--config", str(config), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "grid[0].components: must be a positive integer, got -3" in err
    assert "Traceback" not in err and not out.exists()


def test_not_toml_and_missing_file(tmp_path):
    bad = tmp_path / "x.toml"
    bad.write_text("name = \n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_config(tmp_path / "missing.toml")


def test_rules_skip_invalid_and_collapse_settings_that_do_not_apply():
    config = parse_config({
        "name": "t", "fixed": {"task": "image", "size": 16, "components": 20},
        "grid": [
            # batch fits: order/assign do not apply, so 3 x 2 combinations make 1 cell
            {"dataset": "astronaut", "stream": "none", "order": ["sequential", "reversed",
                                                                 "shuffled"],
             "assign": ["prior", "posterior"], "method": ["vbgs", "gradient"]},
            # patch streams: every order x assign is its own cell; iters does not apply
            {"dataset": "astronaut", "stream": "patches", "iters": [2, 3],
             "order": ["sequential", "reversed"], "assign": ["prior", "posterior"]},
        ]}, "rules.toml")
    plan = expand(config)
    cells = [c.as_dict() for c in plan.cells]
    batch = [c for c in cells if c["stream"] == "none"]
    stream = [c for c in cells if c["stream"] == "patches"]
    assert len(batch) == 2 and all("order" not in c and "assign" not in c for c in batch)
    assert {c["method"] for c in batch} == {"vbgs", "gradient"}
    assert len(stream) == 4 and all("iters" not in c for c in stream)
    reasons = [s.reason for s in plan.skipped]
    assert sum(r.startswith("same cell as") and "order dropped" in r for r in reasons) == 10
    assert sum("iters dropped" in r for r in reasons) == 4
    assert len(cells) + len(plan.skipped) == 6 * 2 + 2 * 2 * 2


def test_cell_key_is_stable_and_depends_on_settings_and_version():
    a = {"task": "image", "dataset": "astronaut", "components": 20}
    assert cell_key(a, "1") == cell_key(dict(reversed(list(a.items()))), "1")
    assert cell_key(a, "1") != cell_key({**a, "components": 21}, "1")
    assert cell_key(a, "1") != cell_key(a, "2")


def test_grids_that_make_no_cells_are_refused(tmp_path, capsys):
    config = tmp_path / "none.toml"
    config.write_text('name = "none"\n[[grid]]\ntask = "image"\ndataset = "astronaut"\n'
                      'method = "gradient"\nstream = "patches"\n')
    assert main(["sweep", "--config", str(config), "--out", str(tmp_path / "res")]) == 2
    err = capsys.readouterr().err
    assert "the grids make no cells" in err and "patch streams are VBGS only" in err


def test_bundled_configs_by_name(tmp_path):
    from experiments.sweep.cli import _config_path

    assert _config_path("quick") == CONFIGS / "quick.toml"
    assert _config_path("paper") == CONFIGS / "paper.toml"
    own = tmp_path / "mine.toml"
    assert _config_path(str(own)) == own


def test_the_code_version_changes_with_the_source(tmp_path, monkeypatch):
    """Cells made by other code are not resumed: the version in every key fingerprints
    the packages' sources, not only the release number (which stayed 0.1.0)."""
    import sys

    from experiments.sweep.cells import source_fingerprint

    pkg = tmp_path / "fakepkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("A = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    before = source_fingerprint(("fakepkg",))
    assert before == source_fingerprint(("fakepkg",)) and len(before) == 12
    (pkg / "__init__.py").write_text("A = 2\n")
    assert source_fingerprint(("fakepkg",)) != before
    (pkg / "more.py").write_text("")
    sys.modules.pop("fakepkg", None)
    assert len({before, source_fingerprint(("fakepkg",))}) == 2


def test_a_scene_size_is_a_wxh_string():
    """``size = "640x480"`` (a string: a TOML list would be a grid of sizes)."""
    config = parse_config({"name": "t", "fixed": {"size": "48x32"},
                           "grid": [{"task": "scene", "dataset": "room"}]}, "ok.toml")
    assert config.grids[0].as_dict()["size"] == ("48x32",)


def test_a_splat_scale_is_a_number_or_auto():
    """``splat_scale = "auto"`` (VBGS chooses it on the arrived frames) or a number."""
    doc = {"name": "t", "grid": [{"task": "scene", "dataset": "object", "size": 16,
                                  "components": 100, "splat_scale": ["auto", 1.35, 1]}]}
    cells = expand(parse_config(doc, "ok.toml")).cells
    assert [c.as_dict()["splat_scale"] for c in cells] == ["auto", 1.35, 1]


def test_a_nested_constant_is_a_dotted_setting():
    """``evidence.forget_after = [6, 0]`` (a TOML dotted key) sweeps the map's constant:
    each value a cell, set in the task's nested config; dropped for the gradient baseline,
    which has no such map; a value the config refuses is refused before any cell runs."""
    import tomllib

    from experiments.sweep.tasks import build_task

    doc = tomllib.loads('name = "t"\n[[grid]]\ntask = "scene"\ndataset = "object-change"\n'
                        'method = ["vbgs", "gradient"]\nevidence.forget_after = [6, 0]\n'
                        'evidence.recolour_sigmas = 4\n')
    cells = [c.as_dict() for c in expand(parse_config(doc)).cells]
    vbgs = sorted((c for c in cells if c["method"] == "vbgs"),
                  key=lambda c: c["evidence.forget_after"])
    assert [c["evidence.forget_after"] for c in vbgs] == [0, 6]
    task = build_task(vbgs[0])
    assert task.evidence.forget_after == 0 and task.evidence.recolour_sigmas == 4
    gradient = [c for c in cells if c["method"] == "gradient"]
    assert len(gradient) == 1 and not any("." in k for k in gradient[0])
    with pytest.raises(ConfigError, match="evidence.forget_after"):
        parse_config({"name": "t", "grid": [{"task": "scene", "dataset": "object",
                                             "evidence": {"forget_after": "six"}}]})
    with pytest.raises(ConfigError, match="evidence.forget_aftr"):
        parse_config({"name": "t", "grid": [{"task": "scene", "dataset": "object",
                                             "evidence": {"forget_aftr": 3}}]})


def test_the_changing_study_config_plans_each_learner():
    cells = [c.as_dict() for c in expand(load_config(CONFIGS / "continual_changing.toml")).cells]
    learners = {(c["method"], c.get("replay", "none"), c.get("evidence.forget_after"),
                 c.get("evidence.recolour_sigmas"), c.get("evidence.recolour_gate"),
                 c.get("from_frame", 0)) for c in cells}
    assert len(cells) == 6 * len(learners) == 60  # three scenes, two seeds
