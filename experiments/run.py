"""``python -m experiments.run COMMAND ...``: fits, benchmarks, sweeps and reports.

Commands:
  fit-image   fit one photo (batch CAVI or a patch stream) and score it
  fit-scene   learn a 3-D splat from a stream of RGB-D frames, score held-out views
  check       a dataset doctor: cameras, depth scale and multi-view consistency of a folder
  write-scene a synthetic scene as a dataset folder, a simulated sensor's depth on its
              training frames (fit-scene --scene FOLDER takes that sensor by default)
  sweep       run a grid of cells from a TOML config (resumable), then report
  report      tables and plots from a sweep's results folder
  depth-study sensor depth against estimated depth (RGB-only path), per method
  tune        choose render settings on validation views (never test views); writes a table
  oracle      render splats built from a view's ground truth: is the renderer right here?
  colour-gap  the streamed (lumped) colour fit against exact least squares (a diagnostic)
  render-bound  VBGS's splats refined by gradient: colours, + opacities, + geometry (a diagnostic)
  front       run time and memory against error: VBGS, VBGS-polish and the gradient baseline
  bench       benchmarks: image, estep, raster, depth
"""

from __future__ import annotations

import argparse
import sys

from experiments.cli_common import (
    SIZE_HELP,
    check_fewer_components,
    check_output_file,
    check_scene_components,
    fail,
    interrupted,
    meaningless_score_warning,
    print_result,
    size_arg,
)
from experiments.inapplicable import given_flags, refuse_inapplicable, watched
from experiments.provenance import record_command, stamp
from experiments.settings import (
    ASSIGN,
    CL_SEGMENTS_DEFAULT,
    COLOUR_RULE,
    DEPTH_KIND,
    DEPTH_REFERENCE,
    DRIFT_DEFAULT,
    ESTEP,
    FORMAT,
    INIT,
    MEASURED_BY,
    METHOD,
    OPACITY_RULE,
    ORDER,
    POSES,
    PROTOCOL,
    REPLAY_DEFAULT,
    SENSOR,
    SENSOR_HOLES_DEFAULT,
    SENSOR_HOLES_HELP,
    STREAM,
    add_choice,
    splat_scale_arg,
)
from vbgs.components import AUTO_MAX_COMPONENTS, components_arg


def _add_fit_image(sub):
    p = sub.add_parser("fit-image", help="fit one photo with VBGS and report PSNR/SSIM")
    p.add_argument("--image", default="astronaut", help="bundled photo name or image file path")
    p.add_argument("--size", type=int, default=64, help="resize to SIZE x SIZE (0: keep)")
    p.add_argument("--components", type=int, default=2000)
    p.add_argument("--iters", type=int, default=10, help="CAVI iterations (batch fits)")
    add_choice(p, "--init", INIT)
    p.add_argument("--seed", type=int, default=0)
    add_choice(p, "--stream", STREAM)
    add_choice(p, "--order", ORDER)
    add_choice(p, "--assign", ASSIGN)
    p.add_argument("--patch", type=int, default=8, help="patch side for --stream patches")
    p.add_argument("--reassign", choices=["on", "off", "auto"], default="auto",
                   help="re-seed unused components (auto: on for batch fits, off for streams)")
    add_choice(p, "--method", METHOD)
    p.add_argument("--steps", type=int, default=2000, help="optimiser steps (gradient)")
    p.add_argument("--save", metavar="PNG", help="write target, render and error side by side")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _fit_image(args) -> dict:
    from experiments.image_task import ImageTask, run_image, save_comparison, task_image
    from vbgs.compilation import cache_root

    reassign = {"on": True, "off": False, "auto": args.stream == "none"}[args.reassign]
    task = ImageTask(image=args.image, size=args.size or None, components=args.components,
                     iters=args.iters, init=args.init, seed=args.seed, stream=args.stream,
                     order=args.order, assign=args.assign, patch=args.patch, reassign=reassign,
                     method=args.method, steps=args.steps)
    check_output_file(args.save, "--save", ".png")  # output paths and sizes before the fit
    root = cache_root()  # bundled photos kept resized: no skimage.transform, no SciPy
    image = task_image(task, cache=root and root / "images")  # once: checked, then fitted
    h, w, _ = image.shape
    check_fewer_components(args.components, h * w, f"{w}x{h} image",
                           "use fewer --components or a larger --size")
    result = run_image(task, progress=True, image=image)
    images = result.pop("images")
    if args.save:
        save_comparison(args.save, images["target"], images["render"],
                        f"{args.image}: {result['psnr']:.2f} dB, {args.components} components")
    return result


def _add_fit_scene(sub):
    p = sub.add_parser("fit-scene", help="learn a 3-D splat from a stream of RGB-D frames")
    p.add_argument("--scene", default="object", help="object | room | walk | a dataset folder")
    add_choice(p, "--format", FORMAT)
    add_choice(p, "--method", METHOD)
    p.add_argument("--components", type=components_arg, default=20000, metavar="K|auto[:MAX]",
                   help="components / splat capacity K, or auto: the count chosen from the "
                        f"data (at most MAX, default {AUTO_MAX_COMPONENTS}; the JSON's "
                        "components_chosen)")
    p.add_argument("--frames", type=int, default=60, help="training frames (at most)")
    p.add_argument("--test-views", type=int, default=8, help="held-out views (at most)")
    p.add_argument("--size", type=size_arg, default=128, help=SIZE_HELP)
    p.add_argument("--budget-points", type=int, default=0, metavar="N",
                   help="VBGS learns at most N points a frame: every s-th pixel per axis from "
                        "a random offset (vbgs.mapping.budget; 0: all)")
    p.add_argument("--budget-saturation", type=int, default=0,  # BudgetConfig's default
                   metavar="N", help="VBGS learns at most about N points per cell of its "
                   "map: points of cells learned that often are skipped before any "
                   "expensive work (vbgs.mapping.saturation; 0: no limit)")
    add_choice(p, "--order", ORDER)
    add_choice(p, "--assign", ASSIGN)
    add_choice(p, "--estep", ESTEP)
    p.add_argument("--candidates", type=int, default=16, help="components per point (sparse)")
    add_choice(p, "--init", INIT)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--opacity", type=float, default=None, help="VBGS splat opacity")
    p.add_argument("--splat-scale", type=splat_scale_arg, default=None,
                   help="VBGS splat covariance scale (sigma multiplier), or auto: the "
                        "scale that draws the arrived training frames best")
    p.add_argument("--splat-blur", type=float, default=None, metavar="PX2",
                   help="VBGS pixel filter: variance (px²) added to each projected splat")
    p.add_argument("--replay", default=REPLAY_DEFAULT,
                   help="gradient, vbgs-polish (continual): none | fifo:K | reservoir:K | full")
    p.add_argument("--steps-per-frame", type=int, default=50,
                   help="gradient, vbgs-polish: steps per arriving frame (continual)")
    p.add_argument("--steps", type=int, default=3000,
                   help="gradient, vbgs-polish: steps on all frames (static protocol)")
    p.add_argument("--anchor", type=float, default=None, metavar="W",
                   help="vbgs-polish: weight of the posterior's anchor on the polished "
                        "splats (0: a free polish; default: vbgs.baseline.anchor."
                        "ANCHOR_WEIGHT continual, 0 static)")
    add_choice(p, "--protocol", PROTOCOL)
    p.add_argument("--cl-segments", type=int, nargs="?", const=CL_SEGMENTS_DEFAULT, default=0,
                   metavar="S",
                   help=f"continual protocol: PSNR on each of S stream segments' test views "
                        f"after each segment (JSON cl_matrix) and its average final PSNR, "
                        f"forgetting and backward transfer (no S: {CL_SEGMENTS_DEFAULT})")
    p.add_argument("--depth-model", metavar="ONNX", help="estimate depth from RGB with this model")
    add_choice(p, "--depth-kind", DEPTH_KIND)
    p.add_argument("--depth-preset", default=None, help="depth model family preset")
    p.add_argument("--depth-align", default="auto",
                   help="auto | none | median | scale-shift | scale-shift-inverse "
                        "(--depth-reference sensor)")
    add_choice(p, "--depth-reference", DEPTH_REFERENCE)
    _add_sensor(p)
    add_choice(p, "--opacity-rule", OPACITY_RULE)
    add_choice(p, "--colour-rule", COLOUR_RULE)
    p.add_argument("--background", default="auto",
                   help="auto (estimated from the pixels without depth of the frames seen) "
                        "or R,G,B in [0, 1]")
    _add_calibration(p)
    add_choice(p, "--poses", POSES)
    p.add_argument("--drift", default=DRIFT_DEFAULT, metavar="SIGMA_T,SIGMA_R",
                   help="--poses odometry: the odometry's error per frame, scene units "
                        "(metres) and degrees (a seeded random walk)")
    p.add_argument("--plot", metavar="PNG", help="--poses track|odometry: top view of the "
                                                 "true, tracked (and odometry) trajectories")
    p.add_argument("--ply", metavar="OUT", help="save the splats as a 3DGS PLY")
    p.add_argument("--save", metavar="PNG", help="ground truth and render of held-out views")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _add_sensor(p):
    """The depth sensor a scene task simulates on its training frames and learns under
    (fit-scene, tune)."""
    # checked by SceneTask, not argparse: a bad name is refused in one line
    p.add_argument("--simulate-sensor", default=SENSOR.default,
                   metavar="{" + ",".join(SENSOR.values) + "}", help=SENSOR.help)
    p.add_argument("--sensor", default=MEASURED_BY.default,
                   metavar="{" + ",".join(MEASURED_BY.values) + "}", help=MEASURED_BY.help)
    p.add_argument("--sensor-level", type=float, default=None, metavar="X",
                   help="noise multiplier of the sensor, simulated (--simulate-sensor) and "
                        "as the learner takes it (--sensor): 0: exact depth values, "
                        "1: the published model, 2: twice its noise (default: the "
                        "folder's record of its sensor, else 1)")
    p.add_argument("--sensor-holes", default=SENSOR_HOLES_DEFAULT, metavar="SPEC",
                   help=SENSOR_HOLES_HELP)


def _sensor_argv(args) -> list[str]:
    """The sensor options of ``args`` (:func:`_add_sensor`) that are not the defaults, as
    command-line words."""
    words = []
    for flag, value, default in (("--simulate-sensor", args.simulate_sensor, SENSOR.default),
                                 ("--sensor", args.sensor, MEASURED_BY.default),
                                 ("--sensor-level", args.sensor_level, None),
                                 ("--sensor-holes", args.sensor_holes, SENSOR_HOLES_DEFAULT)):
        if value != default:
            words += [flag, str(value)]
    return words


def _add_write_scene(sub):
    p = sub.add_parser("write-scene", help="write a synthetic scene as a dataset folder, a "
                                           "simulated sensor's depth on its training frames")
    p.add_argument("--scene", default="object", help="object | room | walk")
    p.add_argument("--size", type=size_arg, default=128, help=SIZE_HELP)
    p.add_argument("--frames", type=int, default=60, help="training frames")
    p.add_argument("--test-views", type=int, default=8, help="held-out test views")
    p.add_argument("--val-views", type=int, default=4, help="validation views")
    p.add_argument("--seed", type=int, default=0,
                   help="the scene's views and the sensor's noise, as fit-scene --seed")
    p.add_argument("--simulate-sensor", default=SENSOR.default,
                   metavar="{" + ",".join(SENSOR.values) + "}", help=SENSOR.help)
    p.add_argument("--sensor-level", type=float, default=1.0, metavar="X",
                   help="noise multiplier of the simulated sensor (0: exact depth values, "
                        "1: the published model, 2: twice its noise)")
    p.add_argument("--sensor-holes", default=SENSOR_HOLES_DEFAULT, metavar="SPEC",
                   help=SENSOR_HOLES_HELP)
    p.add_argument("--format", choices=WRITE_FORMATS, default=WRITE_FORMATS[0],
                   help="dataset layout (blender: train, test and val splits)")
    p.add_argument("--out", required=True, metavar="FOLDER", help="the folder to write")
    p.add_argument("--force", action="store_true", help="write into a non-empty --out")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _write_scene(args) -> dict:
    from experiments.write_scene import write_scene

    return write_scene(args.scene, args.out, size=args.size, frames=args.frames,
                       n_test=args.test_views, n_val=args.val_views, seed=args.seed,
                       sensor=args.simulate_sensor, level=args.sensor_level,
                       holes=args.sensor_holes, format=args.format, force=args.force,
                       progress=True)


WRITE_FORMATS = ("blender",)  # the layouts with separate train, test and val splits


def _add_calibration(p) -> None:
    p.add_argument("--intrinsics", metavar="FX,FY,CX,CY", default=None,
                   help="a dataset folder's camera in pixels of its images as stored, pixel "
                        "centres at integers (default: the folder's, else the format's)")
    p.add_argument("--depth-scale", type=float, default=None, metavar="S",
                   help="depth PNG codes per scene unit (1000: millimetres; default: the "
                        "folder's, else the format's)")


def _calibration(args) -> dict:
    from vbgs.data.calibration import check_depth_scale, check_intrinsics

    out = {}
    if args.intrinsics is not None:
        out["intrinsics"] = tuple(check_intrinsics(args.intrinsics))[:4]
    if args.depth_scale is not None:
        out["depth_scale"] = check_depth_scale(args.depth_scale)
    return out


def _add_check(sub):
    p = sub.add_parser("check", help="a dataset doctor: rotations, intrinsics, depth scale and "
                                     "multi-view consistency; names the likely fix (exit 2 "
                                     "when a check fails)")
    p.add_argument("--scene", required=True, help="a dataset folder (or a synthetic scene name)")
    add_choice(p, "--format", FORMAT)
    p.add_argument("--size", type=int, default=128, help="image size (longer side; 0: keep)")
    p.add_argument("--frames", type=int, default=None, help="training frames (default: all)")
    _add_calibration(p)
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _check(args) -> dict:
    from experiments.check import check_scene

    if args.size < 0 or (args.frames is not None and args.frames < 1):
        raise ValueError(f"--size must be >= 0 and --frames >= 1, got {args.size} and "
                         f"{args.frames}")
    return check_scene(args.scene, args.format, args.size or None, args.frames,
                       **_calibration(args))


def _fit_scene(args) -> dict:
    from experiments.scene_task import SceneTask, run_scene, save_views
    from vbgs.mapping import BudgetConfig

    render = {k: v for k, v in (("opacity", args.opacity), ("splat_scale", args.splat_scale),
                                ("splat_blur", args.splat_blur),
                                ("polish_anchor", args.anchor)) if v is not None}
    task = SceneTask(scene=args.scene, format=args.format, method=args.method,
                     components=args.components, frames=args.frames, n_test=args.test_views,
                     size=args.size, order=args.order, assign=args.assign, estep=args.estep,
                     candidates=args.candidates, init=args.init, seed=args.seed,
                     replay=args.replay, steps_per_frame=args.steps_per_frame, steps=args.steps,
                     protocol=args.protocol, cl_segments=args.cl_segments,
                     depth_model=args.depth_model,
                     depth_kind=args.depth_kind, depth_preset=args.depth_preset,
                     depth_align=args.depth_align, depth_reference=args.depth_reference,
                     background=args.background,
                     opacity_rule=args.opacity_rule, colour_rule=args.colour_rule,
                     simulate_sensor=args.simulate_sensor, sensor_level=args.sensor_level,
                     sensor_holes=args.sensor_holes, sensor=args.sensor, poses=args.poses,
                     drift=args.drift, budget=BudgetConfig(points=args.budget_points,
                                                               saturation=args.budget_saturation),
                     **_calibration(args),
                     **render)
    if args.test_views < 1:  # checks before the fit: output paths, sizes, held-out views
        raise ValueError(f"--test-views must be at least 1 (the scores are measured on "
                         f"held-out views), got {args.test_views}")
    check_output_file(args.save, "--save", ".png")
    check_output_file(args.ply, "--ply", ".ply")
    check_output_file(args.plot, "--plot", ".png")
    if args.plot and args.poses == "given":
        raise ValueError("--plot draws the tracked trajectory: give --poses track or odometry")
    check_scene_components(args.components, args.frames, args.size)
    if args.anchor is not None and args.method != "vbgs-polish":
        raise ValueError(f"--anchor weighs the polish of --method vbgs-polish; "
                         f"--method {args.method} has none: drop --anchor")
    result = run_scene(task, progress=True, ply=args.ply)
    if args.save:
        save_views(args.save, result.images["target"], result.images["render"],
                   f"{args.scene}, {args.method}: {result.psnr:.2f} dB held-out")
    out = result.to_dict(images=False)
    if args.plot:
        from experiments.tracking import save_trajectory_plot

        save_trajectory_plot(args.plot, out, f"{args.scene}, --poses {args.poses}: ATE RMSE "
                                             f"{out['ate_rmse']:.4f}")
    return out


# opacity comes from evidence (the default); scale and pixel filter are chosen together
DEFAULT_GRID = ["splat_scale=0.85,1.0,1.2,1.4,1.6", "splat_blur=0,0.02,0.05,0.1,0.15,0.3"]


def _add_tune(sub):
    p = sub.add_parser("tune", help="learn one stream, then score a grid of render settings "
                                    "on validation views; writes OUT/SCENE.csv and .md")
    p.add_argument("--scene", nargs="+", default=["object"],
                   help="object | room | walk | a dataset folder; several: each gets its table and "
                        "OUT/mean.csv ranks the settings by their mean over the scenes")
    add_choice(p, "--format", FORMAT)
    add_choice(p, "--method", METHOD)
    p.add_argument("--components", type=components_arg, default=20000, metavar="K|auto[:MAX]")
    p.add_argument("--frames", type=int, default=60, help="training frames (at most)")
    p.add_argument("--val-views", type=int, default=4, help="validation views (at most)")
    p.add_argument("--size", type=size_arg, default=128, help=SIZE_HELP)
    add_choice(p, "--order", ORDER)
    add_choice(p, "--assign", ASSIGN)
    add_choice(p, "--init", INIT)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--background", default="auto", help="auto or R,G,B in [0, 1]")
    add_choice(p, "--protocol", PROTOCOL)
    p.add_argument("--steps", type=int, default=3000,
                   help="gradient: steps on all frames (static protocol)")
    p.add_argument("--steps-per-frame", type=int, default=50,
                   help="gradient: steps per arriving frame (continual)")
    p.add_argument("--replay", default=REPLAY_DEFAULT,
                   help="gradient (continual): none | fifo:K | reservoir:K | full")
    _add_sensor(p)
    p.add_argument("--grid", nargs="+", default=DEFAULT_GRID, metavar="NAME=V1,V2",
                   help="render settings (task fields) and their values, e.g. "
                        "splat_scale=0.5,0.7,1.0 opacity=0.5,0.9; model hyperparameters as "
                        "prior.NAME (e.g. prior.cov_scale=0.2,0.5: one stream per value) "
                        "(default: %(default)s)")
    p.add_argument("--out", default="runs/tune", help="folder for SCENE.csv and SCENE.md "
                   "(default runs/tune, ignored by git; committed tables name results/...)")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _tune(args) -> dict:
    from pathlib import Path

    from experiments.scene_task import SceneTask, prepare_scene
    from experiments.tune import (
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
              if args.method == "gradient" else []), *_sensor_argv(args),
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
        files += write_tuning(rows, args.out, name, command_line(argv), _inert_note(about, inert))
    if len(per_scene) > 1:  # one setting for every scene: the best mean
        rows = mean_over_scenes(per_scene, grid)
        about = (f"Validation PSNR, SSIM and depth L1 of each setting averaged over the scenes "
                 f"{', '.join(per_scene)} (their own tables beside this one), each "
                 f"{stream}. Best mean PSNR first: the setting to use for all of them.")
        inert = inert_parameters(rows, grid)
        files += write_tuning(rows, args.out, "mean", command_line(argv), _inert_note(about, inert))
    best = {k: v for k, v in rows[0].items() if k not in inert}  # inert values mean nothing
    return {"best": best, "rows": rows, "no_effect": inert, "files": [str(p) for p in files]}


def _inert_note(about: str, inert: list[str]) -> str:
    """``about`` plus a line naming grid parameters that changed no score."""
    if not inert:
        return about
    return (about + f" No effect on any score: {', '.join(inert)} (the learner does not use "
            f"it under these settings).")


def _add_depth_study(sub):
    p = sub.add_parser("depth-study", help="sensor vs estimated depth (ONNX test model)")
    # defaults: the settings of the committed results/depth_study (minutes on 2 cores)
    p.add_argument("--scene", default="object")
    p.add_argument("--components", type=int, default=5000)
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--methods", nargs="+", choices=METHOD.values, default=["vbgs", "gradient"])
    p.add_argument("--steps-per-frame", type=int, default=50, help="gradient, continual")
    p.add_argument("--out", default="runs/depth_study",
                   help="output folder (default runs/depth_study, ignored by git)")
    p.add_argument("--json", action="store_true")


def _depth_study(args) -> dict:
    from experiments.bench import write_table
    from experiments.depth_study import require_onnx, run_depth_study, study_command, study_settings

    require_onnx()  # before any work

    task_kw = dict(scene=args.scene, components=args.components, frames=args.frames,
                   size=args.size, steps_per_frame=args.steps_per_frame)
    rows = run_depth_study(args.out, methods=args.methods, progress=True,
                           **task_kw)
    paths = write_table(rows, args.out, "depth_study",
                        command=study_command(task_kw, args.methods, args.out),
                        settings=study_settings(task_kw, args.methods))
    return {"rows": rows, "files": [str(p) for p in paths]}


def _add_oracle(sub):
    p = sub.add_parser("oracle", help="splats from a view's ground truth, rendered back (the "
                                      "renderer's check, apart from any learner)")
    p.add_argument("--scene", default="object",
                   help="object | room | walk | motorcycle (one real RGB-D view) | a dataset folder")
    add_choice(p, "--format", FORMAT)
    p.add_argument("--frames", type=int, default=60, help="training frames (at most)")
    p.add_argument("--size", type=size_arg, default=128, help=SIZE_HELP)
    p.add_argument("--view", type=int, default=0, help="source training frame")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _oracle(args) -> dict:
    from dataclasses import asdict

    from experiments.oracle import oracle_score
    from experiments.scene_task import SceneTask, load_task_scene

    task = SceneTask(scene=args.scene, format=args.format, frames=args.frames, n_test=1,
                     size=args.size, seed=args.seed)
    return {"scene": args.scene, **asdict(oracle_score(load_task_scene(task), args.view))}


def _add_diagnostic_scene(p) -> None:
    """The scene arguments of a diagnostic command (colour-gap, render-bound): one VBGS
    stream, scored on held-out test views."""
    p.add_argument("--scene", default="object", help="object | room | walk | a dataset folder")
    add_choice(p, "--format", FORMAT)
    p.add_argument("--components", type=int, default=20000)
    p.add_argument("--frames", type=int, default=60, help="training frames (at most)")
    p.add_argument("--test-views", type=int, default=8, help="held-out views (at most)")
    p.add_argument("--size", type=size_arg, default=128, help=SIZE_HELP)
    add_choice(p, "--init", INIT)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _diagnostic_task(args, count: str, **settings):
    """The SceneTask of a diagnostic, checked before any work: ``--test-views`` and the
    flag named ``count`` at least 1, fewer components than pixels."""
    value = getattr(args, count.replace("-", "_"))
    if args.test_views < 1 or value < 1:
        raise ValueError(f"--test-views and --{count} must be at least 1, got "
                         f"{args.test_views} and {value}")
    from experiments.scene_task import SceneTask

    task = SceneTask(scene=args.scene, format=args.format, components=args.components,
                     frames=args.frames, n_test=args.test_views, n_val=0, size=args.size,
                     init=args.init, seed=args.seed, **settings)
    check_scene_components(args.components, args.frames, args.size)
    return task


def _diagnostic_header(args) -> dict:
    return {"scene": args.scene, "components": args.components, "frames": args.frames,
            "size": args.size, "init": args.init}


def _add_colour_gap(sub):
    p = sub.add_parser("colour-gap", help="held-out scores of the streamed colour fit against "
                                          "exact least squares and the posterior colours")
    _add_diagnostic_scene(p)
    p.add_argument("--iterations", type=int, default=30, help="conjugate-gradient iterations")
    p.add_argument("--ridge", type=float, default=None,
                   help="colour ridge in pixels (default: the task's, vbgs.render.colour_fit.RIDGE)")


def _colour_gap(args) -> dict:
    from experiments.colour_gap import colour_gap
    from experiments.scene_task import load_task_scene

    task = _diagnostic_task(args, "iterations",
                            **({} if args.ridge is None else {"colour_ridge": args.ridge}))
    gap = colour_gap(task, load_task_scene(task), iterations=args.iterations,
                     progress=True)
    return {**_diagnostic_header(args), "ridge": task.colour_ridge, **gap}


def _add_render_bound(sub):
    p = sub.add_parser("render-bound", help="held-out scores of VBGS's splats refined by Adam on "
                                            "every training frame: colours, colours and "
                                            "opacities, everything (a diagnostic)")
    _add_diagnostic_scene(p)
    p.add_argument("--steps", type=int, default=900, help="Adam steps of each refinement")


def _render_bound(args) -> dict:
    from experiments.render_bound import render_bound
    from experiments.scene_task import load_task_scene

    task = _diagnostic_task(args, "steps")
    bound = render_bound(task, load_task_scene(task), steps=args.steps,
                         progress=True)
    return {**_diagnostic_header(args), **bound}


def _add_front(sub):
    p = sub.add_parser("front", help="PSNR / SSIM / depth L1 against wall time and replay "
                                     "memory: VBGS, VBGS-polish and the gradient baseline at "
                                     "several step counts; CSV, markdown and a PNG")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--scene", help="object | room | walk | a dataset folder")
    what.add_argument("--image", help="a bundled photo or an image file: VBGS against the "
                                      "2-D gradient baseline")
    what.add_argument("--replot", metavar="CSV", help="draw a front's PNG again from its "
                      "CSV (beside it), running nothing")
    p.add_argument("--title", default=None, help="--replot: the plot's title (default: "
                   "the CSV's title column)")
    add_choice(p, "--format", FORMAT)
    p.add_argument("--size", type=int, default=None,
                   help="image size (default: 128 for scenes, 256 for images)")
    p.add_argument("--components", default=None, metavar="K[,K...]",
                   help="components / splats (default: 20000 for scenes; 2000,8000,16000 "
                        "for images); scenes take one count")
    p.add_argument("--frames", type=int, default=60, help="training frames (at most)")
    p.add_argument("--test-views", type=int, default=8, help="held-out views (at most)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--polish-steps", default="30,100,300,900", metavar="N,N",
                   help="vbgs-polish static step counts")
    p.add_argument("--gradient-steps", default=None, metavar="N,N",
                   help="gradient step counts (default: 100,300,900,3000 for scenes, "
                        "100,300,1000,3000 for images)")
    p.add_argument("--replays", default="none,fifo:8",
                   help="continual rows: replay buffers, comma-separated ('' for none)")
    p.add_argument("--steps-per-frame", type=int, default=20, help="continual rows")
    p.add_argument("--iters", type=int, default=10, help="images: VBGS's CAVI iterations")
    p.add_argument("--out", default=None, help="folder for NAME.csv, .md and .png "
                   "(default runs/front/NAME, ignored by git)")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _front(args) -> dict:
    from pathlib import Path

    from experiments.front import FrontPlan, parse_counts, write_front

    if args.replot:
        from experiments.front import plot_front, read_front

        csv = Path(args.replot)
        if not csv.is_file():
            raise ValueError(f"--replot {csv}: no such CSV (a front's NAME.csv)")
        rows = read_front(csv)
        title = args.title or str(rows[0].get("title", csv.stem))
        plot_front(rows, csv.with_suffix(".png"), title)
        return {"files": [str(csv.with_suffix(".png"))]}
    name = Path(args.scene or args.image).name or "front"
    out = Path(args.out or Path("runs/front") / name)
    image = args.image is not None
    size = args.size or (256 if image else 128)
    components = parse_counts(args.components or ("2000,8000,16000" if image else "20000"),
                              "--components")
    gradient = parse_counts(args.gradient_steps or ("100,300,1000,3000" if image
                                                    else "100,300,900,3000"),
                            "--gradient-steps")
    argv = ["front", *(["--image", args.image] if image else ["--scene", args.scene]),
            "--size", str(size), "--components", ",".join(map(str, components)),
            "--gradient-steps", ",".join(map(str, gradient)), "--seed", str(args.seed)]
    if image:
        from experiments.front import run_image_front

        for k in components:
            check_fewer_components(k, size * size, f"a {size}x{size} image",
                                   "use fewer --components or a larger --size")
        argv += ["--iters", str(args.iters)]
        rows = run_image_front(args.image, size, components, args.iters, gradient,
                               seed=args.seed, progress=True)
        title = f"{name}, {size} px"
    else:
        from experiments.front import run_scene_front
        from experiments.scene_task import SceneTask

        if len(components) != 1:
            raise ValueError(f"--components: a scene's front takes one count, got "
                             f"{args.components!r}")
        replays = tuple(r.strip() for r in args.replays.split(",") if r.strip())
        plan = FrontPlan(polish_steps=parse_counts(args.polish_steps, "--polish-steps"),
                         gradient_steps=gradient, replays=replays,
                         steps_per_frame=args.steps_per_frame, continual=bool(replays))
        base = SceneTask(scene=args.scene, format=args.format, components=components[0],
                         frames=args.frames, n_test=args.test_views, n_val=0, size=size,
                         seed=args.seed)
        check_fewer_components(components[0], args.frames * size**2,
                               f"at most {args.frames} frames x {size}x{size}",
                               "use fewer --components, a larger --size or more --frames")
        argv += ["--frames", str(args.frames), "--test-views", str(args.test_views),
                 "--polish-steps", ",".join(map(str, plan.polish_steps)),
                 "--replays", ",".join(replays), "--steps-per-frame", str(args.steps_per_frame)]
        rows = run_scene_front(base, plan, progress=True)
        title = (f"{name}, {size} px, {components[0]} components, {args.frames} frames")
    argv += ["--out", str(out)]
    files = write_front(rows, out, name, command="python -m experiments.run " + " ".join(argv),
                        title=title)
    return {"rows": rows, "files": [str(p) for p in files]}


def _add_bench(sub):
    p = sub.add_parser("bench", help="benchmarks; figures are printed and written as CSV/markdown")
    p.add_argument("target", choices=["image", "estep", "stream", "raster", "depth"],
                   help="image: CAVI per iteration; estep: dense vs sparse per frame; "
                        "stream: seconds per streamed frame end to end, with a profile; "
                        "raster: 3-D rasterizer; depth: ONNX adapter throughput")
    p.add_argument("--sizes", type=size_arg, nargs="+", default=None,
                   help="image sizes (image: 64 128, raster: 128 256, estep: 128)")
    p.add_argument("--components", type=int, nargs="+", default=None,
                   help="component counts (image: 500..8000, estep: 20000 50000)")
    p.add_argument("--iters", type=int, default=3, help="timed CAVI iterations per cell")
    p.add_argument("--frames", type=int, default=60, help="stream: frames streamed per row")
    p.add_argument("--scenes", nargs="+", default=["object", "room"], help="stream: scenes")
    p.add_argument("--search", choices=["auto", "grid", "kdtree"], default="auto",
                   help="stream: sparse candidate search (auto: KD-tree on CPU, grid elsewhere)")
    p.add_argument("--devices", type=int, nargs="+", default=None,
                   help="stream: rows with the components sharded over N devices (host CPUs: "
                        "one process each with N forced host devices), first component count")
    p.add_argument("--impl", choices=["auto", "xla", "pallas"], default="auto",
                   help="raster: compositing code (auto: pallas on a GPU, xla otherwise; "
                        "pallas off a GPU runs in interpret mode, slow)")
    p.add_argument("--out", default="runs/bench", help="folder for the CSV and markdown table "
                   "(default runs/bench, ignored by git)")
    p.add_argument("--json", action="store_true")


def _bench(args) -> dict:
    from experiments import bench

    progress = True
    defaults = {"image": ([64, 128], [500, 1000, 2000, 4000, 8000]),
                "estep": ([128], [20000, 50000]), "raster": ([128, 256], [10_000, 50_000]),
                "stream": ([128], [20000, 50000, 100000]), "depth": ([256], None)}[args.target]
    sizes, components = args.sizes or defaults[0], args.components or defaults[1]
    if args.target == "image":
        rows = bench.bench_image(sizes, components, iters=args.iters, progress=progress)
    elif args.target == "estep":
        rows = bench.bench_estep(components, size=sizes[0], progress=progress)
    elif args.target == "stream":
        from experiments import bench_stream
        from vbgs.data.scene import size_text

        rows = bench_stream.bench_stream(tuple(args.components or (20000, 50000, 100000)),
                                         tuple(args.scenes), frames=args.frames,
                                         sizes=tuple(sizes), search=args.search,
                                         progress=progress)
        devices = []
        if args.devices:
            devices = bench_stream.device_rows(args.devices, (args.components or [20000])[0],
                                               args.scenes[0], frames=args.frames,
                                               size=(args.sizes or [128])[0])
        profile = _stream_profile(args.scenes[0], (args.components or [20000])[0],
                                  (args.sizes or [128])[0], args.search)
        command = " ".join(["python -m experiments.run bench stream --components",
                            *map(str, components), "--scenes", *args.scenes, "--frames",
                            str(args.frames), "--sizes", *map(size_text, sizes),
                            "--search", args.search]
                           + (["--devices", *map(str, args.devices)] if args.devices else []))
        name = bench_stream.table_name()
        paths = bench.write_table(rows, args.out, name, command=command)
        paths += bench.write_table(profile, args.out, f"{name}_profile", command=command)
        if devices:
            paths += bench.write_table(devices, args.out, f"{name}_devices",
                                       command=command, note=bench_stream.DEVICE_NOTE)
        if not args.json:
            from tabulate import tabulate

            print(f"profile of one frame ({args.scenes[0]}, sparse E-step):")
            print(tabulate(profile, headers="keys", floatfmt=".4g", tablefmt="github"))
            print(tabulate(bench_stream.speedups(rows), headers="keys", floatfmt=".3g",
                           tablefmt="github"))
            if devices:
                print("by device count (host devices share this machine's cores):")
                print(tabulate(devices, headers="keys", floatfmt=".4g", tablefmt="github"))
        return {"rows": rows, "speedups": bench_stream.speedups(rows), "profile": profile,
                "devices": devices, "files": [str(p) for p in paths]}
    elif args.target == "raster":
        from experiments.bench_raster import bench_rasterizer, table_name

        rows = bench_rasterizer(sizes=tuple(sizes), counts=tuple(components), impl=args.impl)
    else:
        from depth.bench import bench_adapter

        rows = [bench_adapter(size=sizes[0])]
    command = " ".join(["python -m experiments.run bench", args.target,
                        "--sizes", *map(str, sizes)]
                       + (["--components", *map(str, components)] if components else [])
                       + (["--iters", str(args.iters)] if args.target == "image" else [])
                       + (["--impl", args.impl] if args.target == "raster" else [])
                       + ["--out", str(args.out)])
    name = table_name(args.impl) if args.target == "raster" else f"bench_{args.target}"
    paths = bench.write_table(rows, args.out, name, command=command)
    return {"rows": rows, "files": [str(p) for p in paths]}


def _stream_profile(scene_name: str, k: int, size: int, search: str) -> list[dict]:
    from experiments.bench_stream import _prior, profile_frame
    from vbgs.data.formats import load_scene

    scene = load_scene(scene_name, size=size, n_train=20, n_test=1, seed=0)
    return [{"scene": scene_name, "components": k, **row}
            for row in profile_frame(scene, _prior(scene, k), search=search)]


def _sweep_cli(name: str):
    """A function of :mod:`experiments.sweep.cli`, imported when first called (it
    imports tqdm; start-up time that other commands do not need)."""

    def call(*args):
        from experiments.sweep import cli

        return getattr(cli, name)(*args)

    return call


COMMANDS = {"fit-image": (_add_fit_image, _fit_image), "fit-scene": (_add_fit_scene, _fit_scene),
            "check": (_add_check, _check),
            "write-scene": (_add_write_scene, _write_scene),
            "depth-study": (_add_depth_study, _depth_study), "bench": (_add_bench, _bench),
            "oracle": (_add_oracle, _oracle), "tune": (_add_tune, _tune),
            "colour-gap": (_add_colour_gap, _colour_gap),
            "render-bound": (_add_render_bound, _render_bound),
            "front": (_add_front, _front),
            "sweep": (_sweep_cli("add_sweep"), _sweep_cli("run_sweep")),
            "report": (_sweep_cli("add_report"), _sweep_cli("run_report"))}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The command-line parser; with ``only``, that command's options alone (building
    every command's options imports what they list, e.g. the sweep backends: start-up
    time that a fit does not need)."""
    parser = argparse.ArgumentParser(prog="python -m experiments.run", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    for name, (add, _) in COMMANDS.items():
        if only is None or name == only:
            add(sub)
    return parser


def _command_parser(name: str) -> argparse.ArgumentParser:
    """One command's own parser (its options without the command's name)."""
    sub = argparse.ArgumentParser().add_subparsers()
    COMMANDS[name][0](sub)
    return sub.choices[name]


def main(argv: list[str] | None = None, program: str = "python -m experiments.run") -> int:
    """Run one command; ``program`` is what the records name before ``argv``."""
    argv = sys.argv[1:] if argv is None else list(argv)
    record_command(argv, program)  # every record and table names the command and the code
    try:  # building the parser imports modules: Ctrl-C there ends cleanly too
        command = argv[0] if argv and argv[0] in COMMANDS else None  # else: all, for help
        args = build_parser(command).parse_args(argv)
        if watched(args.command):  # flags given that do not apply: refused, saying why
            given = given_flags(_command_parser(args.command), argv[1:], watched(args.command))
            refuse_inapplicable(args.command, args, given)
        from vbgs.compilation import CompileTimer, enable_persistent_cache

        enable_persistent_cache()  # opt out with VBGS_NO_COMPILE_CACHE=1
        timer = CompileTimer()
        with timer:
            result = COMMANDS[args.command][1](args)
    except (ValueError, TypeError, OSError, ImportError) as err:  # OSError: a file that cannot
        # be written; ImportError: an optional dependency a command needs is missing
        return fail(err, as_json="--json" in argv)
    except KeyboardInterrupt as err:  # Ctrl-C: one line, status 130, no traceback
        return interrupted(err)
    if args.command in ("fit-image", "fit-scene"):
        result["compile_seconds"] = timer.seconds  # all compilation (or cache loads) in the run
    if args.command == "check" and "error" in result:  # the report, then the verdict: exit 2
        print_result(args.command, stamp(result), as_json=args.json)
        return fail(ValueError(result["error"]))
    warning = meaningless_score_warning(result)
    if warning:
        result["warning"] = warning
    result = stamp(result)
    print_result(args.command, result, as_json=getattr(args, "json", False))
    if warning:
        print(warning, file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
