"""``tune``: learn one stream, then choose render settings on validation views (never test
views); writes a table per scene and, for several scenes, their mean."""

from __future__ import annotations

from experiments.cli.options import (
    SCENE_HELP,
    add_frames,
    add_json,
    add_scene_size,
    add_seed,
    add_sensor,
    add_val_views,
    sensor_argv,
)
from experiments.cli.output import check_scene_components
from experiments.tasks.settings import (
    ASSIGN,
    FORMAT,
    INIT,
    METHOD,
    ORDER,
    PROTOCOL,
    REPLAY_DEFAULT,
    add_choice,
)
from vbgs.components import components_arg

DEFAULT_GRID = ["splat_scale=0.85,1.0,1.2,1.4,1.6", "splat_blur=0,0.02,0.05,0.1,0.15,0.3"]


def add(sub):
    p = sub.add_parser("tune", help="learn one stream, then score a grid of render settings "
                                    "on validation views; writes OUT/SCENE.csv and .md")
    p.add_argument("--scene", nargs="+", default=["object"],
                   help=f"{SCENE_HELP}; several: each gets its table and OUT/mean.csv "
                        "ranks the settings by their mean over the scenes")
    add_choice(p, "--format", FORMAT)
    add_choice(p, "--method", METHOD)
    p.add_argument("--components", type=components_arg, default=20000, metavar="K|auto[:MAX]")
    add_frames(p)
    add_val_views(p)
    add_scene_size(p)
    add_choice(p, "--order", ORDER)
    add_choice(p, "--assign", ASSIGN)
    add_choice(p, "--init", INIT)
    add_seed(p)
    p.add_argument("--background", default="auto", help="auto or R,G,B in [0, 1]")
    add_choice(p, "--protocol", PROTOCOL)
    p.add_argument("--steps", type=int, default=3000,
                   help="gradient: steps on all frames (static protocol)")
    p.add_argument("--steps-per-frame", type=int, default=50,
                   help="gradient: steps per arriving frame (continual)")
    p.add_argument("--replay", default=REPLAY_DEFAULT,
                   help="gradient (continual): none | fifo:K | reservoir:K | full")
    add_sensor(p)
    p.add_argument("--grid", nargs="+", default=DEFAULT_GRID, metavar="NAME=V1,V2",
                   help="render settings (task fields) and their values, e.g. "
                        "splat_scale=0.5,0.7,1.0 opacity=0.5,0.9; model hyperparameters as "
                        "prior.NAME (e.g. prior.cov_scale=0.2,0.5: one stream per value) "
                        "(default: %(default)s)")
    p.add_argument("--out", default="runs/tune", help="folder for SCENE.csv and SCENE.md "
                   "(default runs/tune, ignored by git; committed tables name results/...)")
    add_json(p)


def run(args) -> dict:
    from pathlib import Path

    from experiments.tasks.scene_task import SceneTask, prepare_scene
    from experiments.studies.tune import (
        command_line,
        inert_parameters,
        mean_over_scenes,
        parse_grid,
        tune,
        write_tuning,
    )
    from vbgs.data.scene import size_text

    if args.val_views < 1:
        raise ValueError(f"--val-views must be at least 1 (settings are chosen on them), "
                         f"got {args.val_views}")
    names = [Path(s).name or "scene" for s in args.scene]
    if len(set(names)) != len(names):
        raise ValueError(f"--scene: two scenes share the name {names!r}; each writes "
                         f"OUT/NAME.csv, so give folders with different names")
    tasks = [SceneTask(scene=scene, format=args.format, method=args.method,
                       components=args.components, frames=args.frames, n_test=1,
                       n_val=args.val_views, size=args.size, order=args.order,
                       assign=args.assign, init=args.init, seed=args.seed,
                       background=args.background, protocol=args.protocol, steps=args.steps,
                       steps_per_frame=args.steps_per_frame, replay=args.replay,
                       simulate_sensor=args.simulate_sensor, sensor=args.sensor,
                       sensor_level=args.sensor_level, sensor_holes=args.sensor_holes)
             for scene in args.scene]
    grid = parse_grid(args.grid, tasks[0])  # bad grids fail before any work
    check_scene_components(args.components, args.frames, args.size)
    argv = ["tune", "--scene", *args.scene, *(["--format", args.format] if args.format else []),
            "--method", args.method, "--components", str(args.components),
            "--frames", str(args.frames), "--val-views", str(args.val_views),
            "--size", size_text(args.size), "--order", args.order, "--assign", args.assign,
            "--init", args.init, "--seed", str(args.seed), "--background", args.background,
            *(["--protocol", args.protocol, "--steps", str(args.steps), "--steps-per-frame",
               str(args.steps_per_frame), "--replay", args.replay]
              if args.method == "gradient" else []), *sensor_argv(args),
            "--grid", *args.grid, "--out", args.out]
    per_scene, files, stream = {}, [], f"streamed once ({args.order}, {args.assign} assignment)"
    if args.method == "gradient":
        stream = (f"learned by the gradient baseline in {args.steps} steps on all of them"
                  if args.protocol == "static" else
                  f"streamed once (gradient baseline, {args.steps_per_frame} steps per "
                  f"frame, replay {args.replay})")
    for task, name in zip(tasks, names, strict=True):
        scene = prepare_scene(task)[0]  # a simulated sensor's depth on the training frames
        rows = tune(task, scene, grid, progress=True)
        about = (f"{len(scene.train)} training frames {stream}; scores are "
                 f"means over {len(scene.val)} validation views (no test view is rendered). "
                 f"Best first.")
        per_scene[name], inert = rows, inert_parameters(rows, grid)
        files += write_tuning(rows, args.out, name, command_line(argv), inert_note(about, inert))
    if len(per_scene) > 1:  # one setting for every scene: the best mean
        rows = mean_over_scenes(per_scene, grid)
        about = (f"Validation PSNR, SSIM and depth L1 of each setting averaged over the scenes "
                 f"{', '.join(per_scene)} (their own tables beside this one), each "
                 f"{stream}. Best mean PSNR first: the setting to use for all of them.")
        inert = inert_parameters(rows, grid)
        files += write_tuning(rows, args.out, "mean", command_line(argv), inert_note(about, inert))
    best = {k: v for k, v in rows[0].items() if k not in inert}  # inert values mean nothing
    return {"best": best, "rows": rows, "no_effect": inert, "files": [str(p) for p in files]}


def inert_note(about: str, inert: list[str]) -> str:
    """``about`` plus a line naming grid parameters that changed no score."""
    if not inert:
        return about
    return (about + f" No effect on any score: {', '.join(inert)} (the learner does not use "
            f"it under these settings).")
