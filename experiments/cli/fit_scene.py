"""``fit-scene``: learn a 3-D splat from a stream of RGB-D frames, score held-out views."""

from __future__ import annotations

import argparse
from pathlib import Path

from experiments.cli.options import (
    add_calibration,
    add_frames,
    add_json,
    add_scene,
    add_scene_size,
    add_seed,
    add_sensor,
    add_test_views,
    calibration,
)
from experiments.cli.output import check_output_file, check_scene_components
from experiments.tasks.settings import (
    ASSIGN,
    CL_SEGMENTS_DEFAULT,
    COLOUR_RULE,
    DEPTH_KIND,
    DEPTH_REFERENCE,
    DRIFT_DEFAULT,
    ESTEP,
    SEARCH,
    FORMAT,
    INIT,
    METHOD,
    OPACITY_RULE,
    ORDER,
    POSES,
    PROTOCOL,
    REPLAY_DEFAULT,
    add_choice,
    splat_scale_arg,
)
from vbgs.components import AUTO_MAX_COMPONENTS, components_arg


def add(sub):
    p = sub.add_parser("fit-scene", help="learn a 3-D splat from a stream of RGB-D frames")
    add_scene(p)
    add_choice(p, "--format", FORMAT)
    add_choice(p, "--method", METHOD)
    p.add_argument("--components", type=components_arg, default=20000, metavar="K|auto[:MAX]",
                   help="components / splat capacity K, or auto: the count chosen from the "
                        f"data (at most MAX, default {AUTO_MAX_COMPONENTS}; the JSON's "
                        "components_chosen)")
    add_frames(p)
    add_test_views(p)
    add_scene_size(p)
    p.add_argument("--from-frame", type=int, default=0, metavar="N",
                   help="learn the stream from training frame N on: a fresh map of what "
                        "those frames show (after a changing scene's last change, its world "
                        "as it is now)")
    p.add_argument("--hold-seeds", action="store_true",
                   help="VBGS: a component's seed holds its cell as its mean does, so ground "
                        "whose components' means moved away is not grown again (the map's "
                        "growth.hold_seeds)")
    p.add_argument("--hold-paid", action="store_true",
                   help="VBGS: where merged components stood stays held, so a merge pays for "
                        "its ground once (the map's growth.hold_paid)")
    p.add_argument("--through-background", action=argparse.BooleanOptionalAction,
                   default=None,
                   help="VBGS under a measured sensor: pixels that show the background (no "
                        "depth, joined to the border) count as seen through for components "
                        "within the sensor's range, so what left the view against the "
                        "background is forgotten (the map's evidence.through_background; "
                        "on by default, --no-through-background turns it off)")
    p.add_argument("--merge-ahead", type=float, default=None, metavar="SHARE",
                   help="VBGS: once the components are all in use, a round of merges frees "
                        "at least this share of them, so that rounds come less often "
                        "(default: the map's growth.merge_ahead)")
    p.add_argument("--spent-levels", type=_spent_levels, default=None, metavar="J|ground",
                   help="VBGS: once the components are all in use, new ground takes cells "
                        "J levels coarser (2^J times the side), so ground met late costs "
                        "fewer merges of what was learned first; ground: as many levels "
                        "as the ground met so far allows (default: the map's "
                        "growth.spent_levels; 0: the same cells throughout)")
    p.add_argument("--forget-after", type=int, default=None, metavar="N",
                   help="VBGS forgets a component its frames have seen through N times in a "
                        "row, none hitting it: what the world no longer holds (default: "
                        "the map's evidence.forget_after; 0: never)")
    p.add_argument("--recolour-sigmas", type=float, default=None, metavar="S",
                   help="VBGS: a frame whose rays on a component show a mean colour more "
                        "than S colour sigmas from what earlier frames' rays showed on it "
                        "counts toward forgetting it (a repainted surface; in a run of its "
                        "own behind --recolour-gate; default: 4 with exact depth, 0, colour "
                        "tells no change, under a measured --sensor)")
    p.add_argument("--recolour-reference", default=None, metavar="REF",  # the map checks it
                   help="VBGS: what --recolour-sigmas judges a frame's colour against: "
                        "history, the mean of what earlier frames' rays showed (S colour "
                        "sigmas), or posterior, each component's colour posterior (S times "
                        "the distance expected where nothing changed; at 6 the static "
                        "scenes forget nothing; default: the map's "
                        "evidence.recolour_reference)")
    p.add_argument("--recolour-gate", type=float, default=None, metavar="SHARE",
                   help="VBGS: with --recolour-sigmas, a recoloured component is forgotten "
                        "only once the frames' depth has forgotten this share of the "
                        "components (the world has shown it changes): a static scene is "
                        "then what it is with colour off (default: 0.005, the map's "
                        "evidence.recolour_gate; 0: no gate)")
    p.add_argument("--doubt-opacity", type=float, default=None, metavar="O",
                   help="VBGS: frames count toward forgetting a component only once its "
                        "rays' hits against passes give it an expected opacity of O or "
                        "more: a component thinner than a pixel, which the rays pass about "
                        "as often as they hit, is kept (at 0.5 the static scenes forget "
                        "nothing; default: 0.5 with exact depth, 0, any, under a measured --sensor)")
    p.add_argument("--budget-points", type=int, default=80000,  # BudgetConfig's default
                   metavar="N",
                   help="VBGS learns at most N points a frame: every s-th pixel per axis from "
                        "a random offset (vbgs.mapping.budget; default %(default)s: a "
                        "640x480 frame's every other pixel, smaller frames whole; 0: all)")
    p.add_argument("--budget-saturation", type=int, default=0,  # BudgetConfig's default
                   metavar="N", help="VBGS learns at most about N points per cell of its "
                   "map: points of cells learned that often are skipped before any "
                   "expensive work (vbgs.mapping.saturation; 0: no limit)")
    add_choice(p, "--order", ORDER)
    add_choice(p, "--assign", ASSIGN)
    add_choice(p, "--estep", ESTEP)
    p.add_argument("--candidates", type=int, default=None,
                   help="components per point (sparse; default: 8 with exact depth, 16 "
                        "under a measured --sensor)")
    add_choice(p, "--search", SEARCH)
    add_choice(p, "--init", INIT)
    add_seed(p)
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
    add_sensor(p)
    add_choice(p, "--opacity-rule", OPACITY_RULE)
    add_choice(p, "--colour-rule", COLOUR_RULE)
    p.add_argument("--background", default="auto",
                   help="auto (estimated from the pixels without depth of the frames seen) "
                        "or R,G,B in [0, 1]")
    add_calibration(p)
    add_choice(p, "--poses", POSES)
    p.add_argument("--drift", default=DRIFT_DEFAULT, metavar="SIGMA_T,SIGMA_R",
                   help="--poses odometry: the odometry's error per frame, scene units "
                        "(metres) and degrees (a seeded random walk)")
    p.add_argument("--plot", metavar="PNG", help="--poses track|odometry: top view of the "
                                                 "true, tracked (and odometry) trajectories")
    p.add_argument("--ply", metavar="OUT", help="save the splats as a 3DGS PLY")
    p.add_argument("--save-map", metavar="NPZ",
                   help="VBGS: save the map after every frame (vbgs.mapping.save; a run "
                        "stopped midway loses only the frame in flight)")
    p.add_argument("--resume-map", metavar="NPZ",
                   help="VBGS: resume the stream from a saved map (the frames it learned "
                        "are skipped; give the settings it was learned with)")
    p.add_argument("--stage-times", action="store_true",
                   help="VBGS: each stage's seconds a frame in the JSON (stage_seconds, "
                        "the frames seconds_per_frame averages; the stages wait for their "
                        "device work, so frames take a little longer)")
    p.add_argument("--streaming-bound", action="store_true",
                   help="VBGS: the streaming bound in the JSON (stream_bound, "
                        "stream_bound_per_point, ...; vbgs.inference.bound): a second "
                        "E-step of every frame and the KL of every component, outside "
                        "seconds_per_frame but not outside the wall time")
    p.add_argument("--save", metavar="PNG", help="ground truth and render of held-out views")
    add_json(p)



def run(args) -> dict:
    from experiments.tasks.scene_report import save_views
    from experiments.tasks.scene_task import SceneTask, run_scene
    from vbgs.mapping import BudgetConfig

    render = {k: v for k, v in (("opacity", args.opacity), ("splat_scale", args.splat_scale),
                                ("splat_blur", args.splat_blur),
                                ("polish_anchor", args.anchor)) if v is not None}
    task = SceneTask(scene=args.scene, format=args.format, method=args.method,
                     components=args.components, frames=args.frames,
                     from_frame=args.from_frame, n_test=args.test_views,
                     size=args.size, order=args.order, assign=args.assign, estep=args.estep,
                     candidates=args.candidates, search=args.search, init=args.init,
                     seed=args.seed,
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
                     save_map=args.save_map, resume_map=args.resume_map,
                     stage_times=args.stage_times, streaming_bound=args.streaming_bound,
                     **calibration(args),
                     **_evidence(args), **_growth(args),
                     **render)
    if args.test_views < 1:  # checks before the fit: output paths, sizes, held-out views
        raise ValueError(f"--test-views must be at least 1 (the scores are measured on "
                         f"held-out views), got {args.test_views}")
    check_output_file(args.save, "--save", ".png")
    check_output_file(args.ply, "--ply", ".ply")
    check_output_file(args.save_map, "--save-map", ".npz")
    if args.resume_map and not Path(args.resume_map).is_file():
        raise ValueError(f"--resume-map {args.resume_map}: no such file (write one with "
                         f"--save-map)")
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
        from experiments.tasks.tracking import save_trajectory_plot

        save_trajectory_plot(args.plot, out, f"{args.scene}, --poses {args.poses}: ATE RMSE "
                                             f"{out['ate_rmse']:.4f}")
    return out


def _spent_levels(text: str) -> int | str:
    """``--spent-levels``' value: ``ground`` or a whole number (the map checks its range)."""
    if text == "ground":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a whole number of levels or ground, got {text!r}"
                                         ) from None


def _growth(args) -> dict:
    """The task's ``growth`` setting where ``--hold-seeds``, ``--hold-paid``,
    ``--merge-ahead`` or ``--spent-levels`` changes it (else none: the map's defaults)."""
    from vbgs.mapping import GrowthConfig

    given = {name: True for name in ("hold_seeds", "hold_paid") if getattr(args, name)}
    if args.merge_ahead is not None:
        given["merge_ahead"] = args.merge_ahead
    if args.spent_levels is not None:
        given["spent_levels"] = args.spent_levels
    return {"growth": GrowthConfig(**given)} if given else {}


def _evidence(args) -> dict:
    """The task's ``evidence`` setting where ``--forget-after``, ``--recolour-sigmas``,
    ``--recolour-reference``, ``--recolour-gate``, ``--doubt-opacity`` or
    ``--through-background`` changes it
    (else none: the map's defaults)."""
    from vbgs.mapping import EvidenceConfig

    given = {name: value for name, value in (("forget_after", args.forget_after),
                                             ("recolour_sigmas", args.recolour_sigmas),
                                             ("recolour_reference", args.recolour_reference),
                                             ("recolour_gate", args.recolour_gate),
                                             ("doubt_opacity", args.doubt_opacity),
                                             ("through_background",
                                              args.through_background))
             if value is not None}
    return {"evidence": EvidenceConfig(**given)} if given else {}
