"""Tune render settings on validation views: ``python -m experiments.run tune``.

What is still a constant in the picture (today the task's ``opacity`` and
``splat_scale``, read by the VBGS learner when it turns its posterior into splats) is
chosen here, on the scene's validation views (``Scene.val``), never on its test views.

The stream is learned once; each setting of the grid then only re-renders: a shallow
copy of the learner gets the task with that setting (``dataclasses.replace``) and its
``splats()`` are scored by :func:`experiments.tasks.protocol.evaluate_validation`. Data a
learner gathers for a render setting (:data:`GATHERED`, the colour fit) depend on the
other render settings: while it is gathered, the stream is learned once per
combination of the other grid settings. So a grid
parameter is a task field the learner reads at render time (:data:`RENDER_FIELDS`), or
one of how the fit runs that is learned once per value (:data:`RELEARNED`: the
candidate search); fields that change what is learned or scored are refused. The grid is given by name
(``--grid splat_scale=0.5,0.7,1.0 opacity=0.5,0.9``), so a new render setting needs
no change here.

Writes ``<out>/<scene>.csv`` and ``<out>/<scene>.md``, both headed by the command that
made them; rows are sorted by validation PSNR, best first.

The method's other constants, the task's nested configs (``prior``: the
:class:`vbgs.inference.model.PriorConfig`; ``growth`` and ``evidence``: the groups of
:class:`vbgs.mapping.Config`), are tuned on the same views by dotted name: a grid entry
``prior.cov_scale=0.2,0.3,0.5``, ``growth.reach_cells=1.5,2,3`` or
``evidence.pass_sigmas=1,2,3`` changes the fit, so the stream is learned once per value,
and every render setting of the grid is scored on each of those streams. The gradient
baseline's constants are the task's ``baseline`` (:class:`vbgs.baseline.TrainConfig`),
reached the same way (``baseline.lr_means``, ``baseline.depth_weight``,
``baseline.densify.every``); under ``--protocol static`` its run is ``task.steps`` steps
on all training frames, as :func:`experiments.tasks.protocol.static_protocol` trains it.
"""

from __future__ import annotations

import copy
import itertools
import shlex
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pandas as pd

from experiments.benchmarks.bench import machine
from experiments.learners import LEARNERS
from experiments.tasks.protocol import (
    PROGRESS_BLOCK,
    evaluate_validation,
    static_background,
    stream_frames,
)
from experiments.provenance import code_version, first_line
from vbgs.data.streams import stream_order
from vbgs.mapping import dotted_names, get_dotted, with_dotted

# Task fields the learner reads when it turns what it learned into splats: a grid of them
# re-renders one learned stream. Every other task field changes what is learned or what
# is scored, and is refused unless it is one of RELEARNED below.
RENDER_FIELDS = frozenset({"opacity", "splat_scale", "splat_blur", "colour_rule",
                           "colour_ridge"})
# Task fields of how the fit runs, not of what it is shown or scored on: the stream is
# learned once per value, as for a nested method constant (the candidate search and its
# count, the E-step's form).
RELEARNED = frozenset({"search", "candidates", "estep"})

# Render settings whose data a learner gathers while learning, under one value only (the
# VBGS learner gathers the colour least squares only under colour_rule "fit"; the
# "posterior" rule needs nothing gathered). The stream is learned under that value and
# every value of the grid is rendered from it. What is gathered depends on the other
# render settings (the fit's blending weights are rendered with them), so while it is
# gathered the stream is learned once per combination of the other grid settings.
GATHERED = {"colour_rule": "fit"}
# Render settings that only the final solve reads, never what is gathered: no re-learning.
SOLVE_ONLY = frozenset({"colour_ridge"})
# Task fields holding a nested config of method constants, reached as ``NAME.FIELD``: model
# hyperparameters, learned anew for each value (``baseline``: the gradient baseline's
# trainer, vbgs.baseline.TrainConfig, with its densification as ``baseline.densify.NAME``).
NESTED = ("prior", "growth", "evidence", "budget", "baseline")


def is_nested_setting(name: str) -> bool:
    """True for a grid name that names a method constant of a nested config
    (``prior.cov_scale``, ``growth.reach_cells``, ``evidence.pass_sigmas``)."""
    return name.partition(".")[0] in NESTED and "." in name


def is_relearned(name: str) -> bool:
    """True for a grid name whose every value is learned anew: a nested method constant,
    or a task field of :data:`RELEARNED`."""
    return is_nested_setting(name) or name in RELEARNED


def nested_names(task) -> list[str]:
    """Every dotted name the grid accepts: the leaf fields of the task's nested configs."""
    return [n for n in dotted_names(task) if n.partition(".")[0] in NESTED]


def with_setting(task, setting: dict):
    """``task`` with the grid ``setting`` applied: task fields by name, dotted names into
    the task's nested configs (each refuses a value it cannot take)."""
    for name, value in setting.items():
        task = with_dotted(task, name, value) if is_nested_setting(name) else replace(
            task, **{name: value})
    return task


BOOLS = {"true": True, "on": True, "1": True, "false": False, "off": False, "0": False}


def typed(kind: type, text: str):
    """``text`` read as a ``kind`` value; a bool only from true/false, on/off or 1/0
    (``bool("false")`` would be True). A constant whose default is None (chosen per case,
    ``growth.denoise_radius``) reads ``none`` as None and a number as an int where it is
    one, else a float."""
    text = text.strip()
    if kind is type(None):
        if text.lower() == "none":
            return None
        return int(text) if text.lstrip("-").isdigit() else float(text)
    if kind is bool:
        if text.lower() not in BOOLS:
            raise ValueError(text)
        return BOOLS[text.lower()]
    return kind(text)


def _nested_value(kind: type, text: str):
    """A method constant's grid value: :func:`typed`, except that a constant that takes a
    whole number or a word (``growth.spent_levels``: levels, or ``ground``) reads a whole
    number as an int and a word as itself, whichever its default is; the nested config
    then refuses what it does not take, in its own words."""
    text = text.strip()
    if kind is str and text.lstrip("-").isdigit():
        return int(text)
    try:
        return typed(kind, text)
    except ValueError:
        if kind is int and text.isalpha():
            return text
        raise


def parse_grid(specs: list[str], task) -> dict[str, list]:
    """``["name=v1,v2", ...]`` -> ``{name: [v1, v2]}``, each value converted to the type
    of the task's current value of ``name`` (float when that is None)."""
    known = {f.name for f in fields(task)}
    known_prior = set(nested_names(task))
    grid: dict[str, list] = {}
    for spec in specs:
        name, sep, values = spec.partition("=")
        name = name.strip().replace("-", "_")
        if not sep or not name or not values.strip():
            raise ValueError(f"--grid entry {spec!r}: write NAME=V1,V2,... "
                             f"(e.g. splat_scale=0.5,0.7,1.0)")
        if is_nested_setting(name) and name not in known_prior:
            raise ValueError(f"--grid: {name!r} is not a method constant; write one of "
                             f"{', '.join(sorted(known_prior))}")
        tunable = sorted((RENDER_FIELDS | RELEARNED) & known)
        if name not in known and not is_nested_setting(name):
            raise ValueError(f"--grid: {name!r} is not a task setting; settings: "
                             f"{', '.join(tunable)} or a dotted method constant")
        if name in known and name not in RENDER_FIELDS | RELEARNED:
            raise ValueError(f"--grid: {name!r} changes what is learned or scored, so "
                             f"validation views cannot tune it; tunable here: "
                             f"{', '.join(tunable)} (and dotted method constants); compare "
                             f"it with `python -m experiments.run sweep`")
        if name in grid:
            raise ValueError(f"--grid: {name!r} is given twice; list all its values in one entry")
        if is_nested_setting(name):
            kind = type(get_dotted(task, name))
            try:
                grid[name] = [_nested_value(kind, v) for v in values.split(",")]
            except ValueError:
                raise ValueError(f"--grid {name}: cannot read {values!r} as {kind.__name__} "
                                 f"values") from None
            for value in grid[name]:  # the nested config refuses what it cannot take
                with_setting(task, {name: value})
            continue
        current = getattr(task, name)
        kind = float if current is None or isinstance(current, float) else type(current)
        try:
            grid[name] = [typed(kind, v) for v in values.split(",")]
        except ValueError:
            raise ValueError(f"--grid {name}: cannot read {values!r} as {kind.__name__} "
                             f"values") from None
    if not grid:
        raise ValueError("--grid needs at least one NAME=V1,V2,... entry")
    for name, values in grid.items():
        repeated = sorted({str(v) for v in values if values.count(v) > 1})
        if repeated:
            raise ValueError(f"--grid {name}: {', '.join(repeated)} is listed more than once; "
                             f"give each value once (a repeated value makes the table's "
                             f"spread read as if {name} had less effect)")
    return grid


def settings(grid: dict[str, list]) -> list[dict]:
    """Every combination of the grid's values, as ``{name: value}`` dicts."""
    names = list(grid)
    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*grid.values())]


def learn_once(task, scene, *, progress: bool = False):
    """The task's learner after one pass of the training stream, and the background
    estimated over it; under ``protocol="static"`` (a learner that trains on all frames,
    the gradient baseline) after ``task.steps`` steps on all training frames, as
    :func:`experiments.tasks.protocol.static_protocol` trains it."""
    learner = LEARNERS[task.method](task, scene)
    if task.protocol == "static" and "static" in type(learner).PROTOCOLS:
        background = static_background(task, scene)
        frames = learner.static_frames(scene)
        for done in range(0, task.steps, PROGRESS_BLOCK):
            learner.train(frames, min(PROGRESS_BLOCK, task.steps - done), background)
        return learner, background
    background = None
    order = stream_order(len(scene.train), task.order, seed=task.seed)
    for _, frame, background in stream_frames(task, scene, order, progress=progress):
        learner.learn(frame, background)
    return learner, background


def tune(task, scene, grid: dict[str, list], *, progress: bool = False) -> list[dict]:
    """Validation scores of every grid setting on one learned stream, best PSNR first.

    Each row: the setting, then ``val_psnr``, ``val_ssim``, ``val_depth_l1`` (means over
    ``scene.val``), and under ``components = "auto"`` the ``components_used`` it chose."""
    if not scene.val:
        raise ValueError(f"scene {scene.name!r} has no validation views to tune on; "
                         f"use --val-views >= 1")
    LEARNERS[task.method].check(task)
    gather = {name: value for name, value in GATHERED.items()
              if name in grid or getattr(task, name, None) == value}
    relearn = {name: values for name, values in grid.items()
               if is_relearned(name)
               or (gather and name not in gather and name not in SOLVE_ONLY)}
    rows = []
    for fixed in settings(relearn):  # [{}] when nothing is relearned: one stream in all
        learner, background = learn_once(with_setting(task, {**fixed, **gather}), scene,
                                          progress=progress)
        for rendered in settings({n: v for n, v in grid.items() if n not in fixed}):
            setting = {name: {**fixed, **rendered}[name] for name in grid}
            view = copy.copy(learner)  # shares the learned state; only render settings differ
            view.task = with_setting(task, setting)
            ev = evaluate_validation(view.splats(), scene, background, view.blur)
            # components = "auto": the count each setting chose (splats drawn) beside it
            count = ({"components_used": view.splats(drop_unused=True).count}
                     if isinstance(task.components, str) else {})
            rows.append({**setting, "val_psnr": ev.psnr, "val_ssim": ev.ssim,
                         "val_depth_l1": ev.depth_l1, **count})
    return sorted(rows, key=lambda r: -np.nan_to_num(r["val_psnr"], nan=-np.inf))


def inert_parameters(rows: list[dict], grid: dict[str, list]) -> list[str]:
    """Grid parameters whose values never changed a score (e.g. a constant the learner
    ignores under the task's other settings): with the other parameters fixed, every
    value of such a parameter gave the same validation PSNR."""
    inert = []
    for name, values in grid.items():
        if len(values) < 2:
            continue
        groups: dict[tuple, set] = {}
        for row in rows:
            key = tuple((k, row[k]) for k in grid if k != name)
            groups.setdefault(key, set()).add(row["val_psnr"])
        if all(len(scores) == 1 for scores in groups.values()):
            inert.append(name)
    return inert


SCORES = ("val_psnr", "val_ssim", "val_depth_l1")


def mean_over_scenes(per_scene: dict[str, list[dict]], grid: dict[str, list]) -> list[dict]:
    """One row per grid setting: its scores averaged over the scenes (``{name: rows}`` as
    :func:`tune` returns them), with each scene's PSNR beside them; best mean PSNR first."""
    tables = []
    first = next(iter(per_scene.values()))
    scores = [*SCORES, *(["components_used"] if first and "components_used" in first[0] else [])]
    own = {"val_psnr": "psnr", "components_used": "components"}  # each scene's, beside
    for name, rows in per_scene.items():
        frame = pd.DataFrame(rows).set_index(list(grid))
        tables.append(frame[scores].rename(columns={k: f"{name}_{v}" for k, v in own.items()})
                      .assign(**{k: frame[k] for k in own if k in scores}))
    joined = pd.concat(tables, keys=list(per_scene), names=["scene"])
    mean = joined.groupby(level=list(grid), sort=False)[scores].mean()
    each = pd.concat([t[[f"{n}_{v}" for k, v in own.items() if k in scores]]
                      for n, t in zip(per_scene, tables, strict=True)], axis=1)
    out = mean.join(each).reset_index()
    out = out.sort_values("val_psnr", ascending=False, key=lambda c: c.fillna(-np.inf))
    return out.to_dict("records")


def write_tuning(rows: list[dict], out_dir: str | Path, name: str, command: str,
                 about: str) -> list[Path]:
    """``name.csv`` and ``name.md`` under ``out_dir``, each headed by ``command`` (CSV:
    ``#`` comment lines, read back with ``pandas.read_csv(path, comment="#")``)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frame = pd.DataFrame(rows)
    header = [f"command: {command}", f"code: {code_version()}", about,
              f"measured on: {machine()}"]
    csv, md = out / f"{name}.csv", out / f"{name}.md"
    csv.write_text("".join(f"# {line}\n" for line in header) + frame.to_csv(index=False))
    md.write_text(f"{first_line()}\n\n# Render settings tuned on validation views: {name}\n\n"
                  f"Command: `{command}`\n\n{about}\n\nMeasured on: {machine()}\n\n"
                  f"{frame.to_markdown(index=False, floatfmt='.4g')}\n")
    return [csv, md]


def command_line(argv: list[str]) -> str:
    """The command that reproduces a run, for the table headers."""
    return "python -m experiments.run " + shlex.join(argv)
