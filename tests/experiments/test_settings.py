"""Settings declared once: CLI defaults equal the task dataclasses' defaults, and the CLI,
the tasks and the sweep validation accept the same choices (experiments.tasks.settings)."""

import dataclasses

import pytest

from experiments.tasks import settings
from experiments.tasks.image_task import ImageTask
from experiments.run import build_parser
from experiments.tasks.scene_task import SceneTask
from experiments.sweep.config import SETTINGS

# CLI flags whose task field has another name, or whose value the command translates.
RENAMED = {"test_views": "n_test", "val_views": "n_val", "image": "image", "scene": "scene"}
NOT_TASK_FIELDS = {"json", "save", "ply", "plot", "out", "grid", "command", "reassign", "opacity",
                   "splat_scale", "splat_blur", "view", "methods", "anchor",
                   "budget_points", "budget_saturation",  # the nested budget.points, .saturation
                   # the nested evidence.* (None: their defaults)
                   "forget_after", "recolour_sigmas", "recolour_reference", "recolour_gate",
                   "doubt_opacity",
                   "hold_seeds", "hold_paid",  # the nested growth.hold_* (off: their defaults)
                   "merge_ahead",  # the nested growth.merge_ahead (None: its default)
                   "spent_levels",  # the nested growth.spent_levels (None: its default)
                   "through_background"}  # the nested evidence.through_background (None: its default)


def _defaults(command: str, argv: list[str] = ()) -> dict:
    return vars(build_parser().parse_args([command, *argv]))


@pytest.mark.parametrize("command, task", [("fit-image", ImageTask), ("fit-scene", SceneTask),
                                           ("tune", SceneTask), ("oracle", SceneTask)])
def test_cli_defaults_equal_the_task_defaults(command, task):
    fields = {f.name: f.default for f in dataclasses.fields(task)}
    checked = 0
    for flag, value in _defaults(command).items():
        if flag in NOT_TASK_FIELDS:
            continue
        name = RENAMED.get(flag, flag)
        assert name in fields, f"{command} --{flag} is not a field of {task.__name__}"
        if command == "tune" and flag == "scene":  # tune takes several scenes
            value, = value
        assert value == fields[name], f"{command} --{flag} defaults to {value!r}, " \
                                      f"{task.__name__}.{name} to {fields[name]!r}"
        checked += 1
    assert checked >= 5  # every command shares at least five settings


def test_budget_flags_default_to_the_budget_config():
    # the nested budget.points and .saturation, declared beside their flags without
    # importing the mapper at parse time
    from vbgs.mapping import BudgetConfig
    flags = _defaults("fit-scene")
    assert flags["budget_points"] == BudgetConfig().points == SceneTask().budget.points
    assert flags["budget_saturation"] == BudgetConfig().saturation


def test_hold_flags_default_to_the_growth_config():
    # the nested growth.hold_seeds and .hold_paid: a flag turns one on, its absence is
    # the map's default (off)
    from vbgs.mapping import GrowthConfig
    flags = _defaults("fit-scene")
    assert flags["hold_seeds"] == GrowthConfig().hold_seeds == SceneTask().growth.hold_seeds
    assert flags["hold_paid"] == GrowthConfig().hold_paid == SceneTask().growth.hold_paid
    assert flags["merge_ahead"] is None  # the map's growth.merge_ahead
    assert flags["spent_levels"] is None  # the map's growth.spent_levels
    from vbgs.mapping import EvidenceConfig
    assert flags["through_background"] is None  # the map's evidence.through_background
    assert EvidenceConfig().through_background is SceneTask().evidence.through_background


def test_fit_image_reassign_auto_matches_the_task_default():
    # --reassign auto means on for a batch fit, which is ImageTask's default
    assert _defaults("fit-image")["reassign"] == "auto" and ImageTask().reassign is True


@pytest.mark.parametrize("key, choice", [("method", settings.METHOD), ("init", settings.INIT),
                                         ("order", settings.ORDER), ("assign", settings.ASSIGN),
                                         ("stream", settings.STREAM), ("estep", settings.ESTEP),
                                         ("format", settings.FORMAT),
                                         ("protocol", settings.PROTOCOL),
                                         ("opacity_rule", settings.OPACITY_RULE),
                                         ("colour_rule", settings.COLOUR_RULE),
                                         ("depth_kind", settings.DEPTH_KIND)])
def test_sweep_validation_and_cli_take_the_same_choices(key, choice):
    assert SETTINGS[key].choices == choice.values
    actions = {a.dest: a for p in build_parser()._subparsers._group_actions[0].choices.values()
               for a in p._actions}
    if key in actions:
        assert tuple(actions[key].choices) == choice.values


def test_declared_choices_match_the_library_tables():
    from experiments.learners import METHODS
    from vbgs.data.formats import LOADERS

    assert settings.METHOD.values == METHODS
    assert settings.FORMAT.values == tuple(LOADERS)


def test_tasks_refuse_values_outside_the_choices():
    with pytest.raises(ValueError, match="unknown protocol 'batch': use one of continual, static"):
        SceneTask(protocol="batch")
    with pytest.raises(ValueError, match="unknown order 'backwards'"):
        ImageTask(order="backwards")
    with pytest.raises(ValueError, match="unknown format 'colmap'"):
        SceneTask(format="colmap")
