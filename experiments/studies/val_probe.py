"""``fit-scene`` scored on validation views in place of its test views.

    python -m experiments.studies.val_probe [--val-views N] fit-scene ARGS...

runs ``python -m experiments.run fit-scene ARGS...`` with the scene's first ``N``
(default 4) validation views as the views it scores, so a constant that ``tune`` cannot
reach (it re-renders one stream, or relearns a nested config of the learner; a stage
before the learner, such as the per-frame depth alignment of :mod:`depth.perframe`, is
neither) is chosen on validation views, never on test views. The test views are not
rendered. Everything else, the JSON record included, is fit-scene's.
"""

from __future__ import annotations

import sys
from dataclasses import replace

import experiments.tasks.scene_task as scene_task
from experiments.run import main as run_main

VAL_VIEWS = 4


def scored_on_validation(n_val: int):
    """A ``load_task_scene`` whose scene's test views are its first ``n_val`` validation
    views (and no validation views are left)."""
    load = scene_task.load_task_scene

    def load_val(task):
        scene = load(replace(task, n_val=n_val))
        if not scene.val:
            raise ValueError(f"scene {task.scene!r} has no validation views to score on")
        return scene._replace(test=scene.val, val=[])

    return load_val


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    n_val, program = VAL_VIEWS, "python -m experiments.studies.val_probe"
    if argv[:1] == ["--val-views"]:
        n_val, argv = int(argv[1]), argv[2:]
        program += f" --val-views {n_val}"
    if n_val < 1:
        raise ValueError(f"--val-views must be at least 1, got {n_val}")
    original = scene_task.load_task_scene
    scene_task.load_task_scene = scored_on_validation(n_val)
    try:
        return run_main(argv, program)
    finally:
        scene_task.load_task_scene = original


if __name__ == "__main__":
    sys.exit(main())
