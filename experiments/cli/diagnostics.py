"""``colour-gap`` and ``render-bound``: two diagnostics of one VBGS stream scored on held-out
views (the streamed colour fit against exact least squares; the splats refined by
gradient: colours, + opacities, + geometry)."""

from __future__ import annotations

from experiments.cli.options import (
    add_frames,
    add_json,
    add_scene,
    add_scene_size,
    add_seed,
    add_test_views,
)
from experiments.cli.output import check_scene_components
from experiments.tasks.settings import FORMAT, INIT, add_choice


def add_diagnostic_scene(p) -> None:
    """The scene arguments of a diagnostic command (colour-gap, render-bound): one VBGS
    stream, scored on held-out test views."""
    add_scene(p)
    add_choice(p, "--format", FORMAT)
    p.add_argument("--components", type=int, default=20000)
    add_frames(p)
    add_test_views(p)
    add_scene_size(p)
    add_choice(p, "--init", INIT)
    add_seed(p)
    add_json(p)


def diagnostic_task(args, count: str, **settings):
    """The SceneTask of a diagnostic, checked before any work: ``--test-views`` and the
    flag named ``count`` at least 1, fewer components than pixels."""
    value = getattr(args, count.replace("-", "_"))
    if args.test_views < 1 or value < 1:
        raise ValueError(f"--test-views and --{count} must be at least 1, got "
                         f"{args.test_views} and {value}")
    from experiments.tasks.scene_task import SceneTask

    task = SceneTask(scene=args.scene, format=args.format, components=args.components,
                     frames=args.frames, n_test=args.test_views, n_val=0, size=args.size,
                     init=args.init, seed=args.seed, **settings)
    check_scene_components(args.components, args.frames, args.size)
    return task


def diagnostic_header(args) -> dict:
    return {"scene": args.scene, "components": args.components, "frames": args.frames,
            "size": args.size, "init": args.init}


def add_colour_gap(sub):
    p = sub.add_parser("colour-gap", help="held-out scores of the streamed colour fit against "
                                          "exact least squares and the posterior colours")
    add_diagnostic_scene(p)
    p.add_argument("--iterations", type=int, default=30, help="conjugate-gradient iterations")
    p.add_argument("--ridge", type=float, default=None,
                   help="colour ridge in pixels (default: the task's, vbgs.render.colour_fit.RIDGE)")


def colour_gap(args) -> dict:
    from experiments.studies import colour_gap as study
    from experiments.tasks.scene_task import load_task_scene

    task = diagnostic_task(args, "iterations",
                            **({} if args.ridge is None else {"colour_ridge": args.ridge}))
    gap = study.colour_gap(task, load_task_scene(task), iterations=args.iterations,
                     progress=True)
    return {**diagnostic_header(args), "ridge": task.colour_ridge, **gap}


def add_render_bound(sub):
    p = sub.add_parser("render-bound", help="held-out scores of VBGS's splats refined by Adam on "
                                            "every training frame: colours, colours and "
                                            "opacities, everything (a diagnostic)")
    add_diagnostic_scene(p)
    p.add_argument("--steps", type=int, default=900, help="Adam steps of each refinement")


def render_bound(args) -> dict:
    from experiments.studies import render_bound as study
    from experiments.tasks.scene_task import load_task_scene

    task = diagnostic_task(args, "steps")
    bound = study.render_bound(task, load_task_scene(task), steps=args.steps,
                         progress=True)
    return {**diagnostic_header(args), **bound}
