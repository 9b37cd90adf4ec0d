"""Which grid combinations make a cell: the validity rules, in one table.

Each rule names a setting, when it applies, and its effect:

* ``skip``: the combination is invalid and no cell is made (logged with the reason);
* ``drop``: the setting has no meaning for this cell, so it is removed from the cell's
  settings; combinations that then coincide collapse into one cell (the others are
  logged as duplicates). A grid may therefore vary ``assign`` next to
  ``method = ["vbgs", "gradient"]`` and get one gradient cell per remaining setting.

After the table, any setting that is neither descriptive (task, dataset, method) nor a
field of the cell's task dataclass is dropped the same way ("not a setting of the image
task"). ``experiments/configs/README.md`` lists the same rules for users.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from experiments.sweep.tasks import DESCRIPTIVE, TASKS, is_nested, task_fields
from vbgs.sensors import HOLED_SENSORS

SKIP, DROP = "skip", "drop"
# The scene task's nested configs that only VBGS's map reads (vbgs.mapping.Config): a
# dotted setting under one (``evidence.forget_after``) is dropped for the gradient
# baseline, one under ``baseline`` (its trainer) for VBGS.
VBGS_CONFIGS = ("prior", "growth", "evidence", "budget")


@dataclass(frozen=True)
class Rule:
    setting: str
    when: Callable[[dict], bool]
    effect: str  # SKIP or DROP
    reason: str


def _gradient(s: dict) -> bool:
    return s.get("method") == "gradient"


def _steps(s: dict) -> bool:
    """The method takes optimiser steps (and a replay buffer, and the protocol choice)."""
    return s.get("method") in ("gradient", "vbgs-polish")


def _batch_image(s: dict) -> bool:
    return s["task"] == "image" and s.get("stream", "none") == "none"


def _streamed_image(s: dict) -> bool:
    return s["task"] == "image" and s.get("stream", "none") != "none"


RULES: tuple[Rule, ...] = (
    # setting       when                                    effect  reason
    Rule("method", lambda s: _streamed_image(s) and _gradient(s), SKIP,
         "patch streams are VBGS only (the gradient image baseline fits all pixels at once)"),
    Rule("method", lambda s: s["task"] == "image" and s.get("method") == "vbgs-polish", SKIP,
         "vbgs-polish is a scene learner (an image has no frames to polish on)"),
    Rule("replay", lambda s: not _steps(s) and s.get("replay", "none") != "none", SKIP,
         "replay buffers belong to the gradient learners; VBGS streams without one"),
    Rule("dataset", lambda s: not TASKS[s["task"]].dataset_exists(s["dataset"]), SKIP,
         "the dataset is another task's built-in dataset"),
    Rule("components", lambda s: isinstance(s["components"], str)
         and (s["task"] == "image" or _gradient(s) or s.get("init", "stream") != "stream"),
         SKIP, "components = \"auto\" is chosen by VBGS's scene stream as frames arrive "
               "(init stream); images, the gradient baseline and oracle starts take a count"),
    Rule("assign", _gradient, DROP, "the gradient baseline has no E-step assignment"),
    Rule("estep", _gradient, DROP, "the gradient baseline has no E-step"),
    Rule("candidates", lambda s: _gradient(s) or s.get("estep") == "dense", DROP,
         "candidates only limit the sparse E-step"),
    Rule("steps_per_frame", lambda s: not _steps(s), DROP,
         "optimiser steps belong to the gradient learners (gradient, vbgs-polish)"),
    Rule("steps", lambda s: not _steps(s), DROP,
         "optimiser steps belong to the gradient learners (gradient, vbgs-polish)"),
    Rule("protocol", lambda s: not _steps(s), DROP,
         "VBGS always streams (the protocol choice is the gradient learners')"),
    Rule("cl_segments", lambda s: _steps(s) and s.get("protocol") == "static", DROP,
         "the continual-learning matrix is measured along a stream; static has none"),
    Rule("order", _batch_image, DROP, "a batch image fit sees all pixels at once"),
    Rule("assign", _batch_image, DROP, "a batch image fit iterates CAVI on all pixels"),
    Rule("patch", _batch_image, DROP, "patches exist only in patch streams"),
    Rule("iters", _streamed_image, DROP, "a patch stream makes one pass over the patches"),
    Rule("iters", lambda s: s["task"] == "image" and _gradient(s), DROP,
         "the gradient image baseline runs `steps` optimiser steps, not CAVI iterations"),
    Rule("steps_per_frame", lambda s: s["task"] == "image", DROP,
         "an image has no frames"),
    Rule("protocol", lambda s: s["task"] == "image", DROP, "an image has no frame stream"),
    Rule("simulate_sensor", lambda s: s["task"] == "image"
         and s.get("simulate_sensor", "exact") != "exact", SKIP,
         "an image has no depth for a simulated sensor to corrupt (its cell would run "
         "without the sensor asked for)"),
    # both methods learn from the same corrupted training frames: no method rule
    Rule("simulate_sensor", lambda s: s.get("simulate_sensor", "exact") != "exact"
         and s.get("depth_model", "sensor") not in ("sensor", "none", "", None), SKIP,
         "a depth model replaces the training depth that the simulated sensor corrupts"),
    Rule("sensor_level", lambda s: s.get("simulate_sensor", "exact") == "exact"
         and s.get("sensor", "exact") == "exact", DROP,
         "the exact sensor adds no noise for a level to scale"),
    Rule("sensor_holes", lambda s: s.get("simulate_sensor", "exact") not in HOLED_SENSORS,
         DROP, "the simulated sensor makes no holes for a spec to set"),
)


@dataclass(frozen=True)
class Verdict:
    settings: dict | None  # the cell's settings, or None when skipped
    reason: str  # why it was skipped, or which settings were dropped and why


def apply_rules(settings: dict) -> Verdict:
    """Apply :data:`RULES` and the task-field filter to one grid combination."""
    s = dict(settings)
    s.setdefault("method", "vbgs")
    dropped = []
    for rule in RULES:
        if rule.setting in s and rule.when(s) and rule.setting not in dict(dropped):
            if rule.effect == SKIP:
                return Verdict(None, f"{rule.setting}={s[rule.setting]!r}: {rule.reason}")
            dropped.append((rule.setting, rule.reason))
    for name, _ in dropped:
        s.pop(name, None)
    for name in sorted(n for n in s if "." in n and is_nested(s["task"], n)):
        head = name.partition(".")[0]
        if head in VBGS_CONFIGS and _gradient(s):
            dropped.append((name, "a constant of VBGS's map; the gradient baseline has none"))
            s.pop(name)
        elif head == "baseline" and s.get("method") == "vbgs":
            dropped.append((name, "a constant of the gradient learners' trainer"))
            s.pop(name)
    fields = task_fields(s["task"]) | set(DESCRIPTIVE)
    for name in sorted(set(s) - fields):
        if "." in name and is_nested(s["task"], name):
            continue  # a dotted setting of the task's nested configs
        dropped.append((name, f"not a setting of the {s['task']} task"))
        s.pop(name)
    return Verdict(s, "; ".join(f"{name} dropped ({why})" for name, why in dropped))
