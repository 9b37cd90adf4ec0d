"""``python -m experiments.run COMMAND ...``: fits, benchmarks, sweeps and reports.

Commands:
  fit-image   fit one photo (batch CAVI or a patch stream) and score it
  fit-scene   learn a 3-D splat from a stream of RGB-D frames, score held-out views
  sweep       run a grid of cells from a TOML config (resumable), then report
  report      tables and plots from a sweep's results folder
  depth-study sensor depth against estimated depth (RGB-only path), per method
  bench       benchmarks: image, estep, raster, depth
"""

from __future__ import annotations

import argparse
import sys

from experiments.cli_common import fail, print_result
from experiments.init_schemes import INIT_HELP, INITS
from experiments.sweep.cli import add_report, add_sweep, run_report, run_sweep


def _add_fit_image(sub):
    p = sub.add_parser("fit-image", help="fit one photo with VBGS and report PSNR/SSIM")
    p.add_argument("--image", default="astronaut", help="bundled photo name or image file path")
    p.add_argument("--size", type=int, default=64, help="resize to SIZE x SIZE (0: keep)")
    p.add_argument("--components", type=int, default=2000)
    p.add_argument("--iters", type=int, default=10, help="CAVI iterations (batch fits)")
    p.add_argument("--init", choices=INITS, default=INITS[0], help=INIT_HELP)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--stream", choices=["none", "patches"], default="none")
    p.add_argument("--order", choices=["sequential", "shuffled", "reversed"], default="sequential")
    p.add_argument("--assign", choices=["prior", "posterior"], default="prior")
    p.add_argument("--patch", type=int, default=8, help="patch side for --stream patches")
    p.add_argument("--reassign", choices=["on", "off", "auto"], default="auto",
                   help="re-seed unused components (auto: on for batch fits, off for streams)")
    p.add_argument("--method", choices=["vbgs", "gradient"], default="vbgs")
    p.add_argument("--steps", type=int, default=2000, help="optimiser steps (gradient)")
    p.add_argument("--save", metavar="PNG", help="write target, render and error side by side")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _fit_image(args) -> dict:
    from experiments.image_task import ImageTask, run_image, save_comparison

    reassign = {"on": True, "off": False, "auto": args.stream == "none"}[args.reassign]
    task = ImageTask(image=args.image, size=args.size or None, components=args.components,
                     iters=args.iters, init=args.init, seed=args.seed, stream=args.stream,
                     order=args.order, assign=args.assign, patch=args.patch, reassign=reassign,
                     method=args.method, steps=args.steps)
    result = run_image(task, progress=sys.stderr.isatty())
    images = result.pop("images")
    if args.save:
        save_comparison(args.save, images["target"], images["render"],
                        f"{args.image}: {result['psnr']:.2f} dB, {args.components} components")
    return result


def _add_fit_scene(sub):
    p = sub.add_parser("fit-scene", help="learn a 3-D splat from a stream of RGB-D frames")
    p.add_argument("--scene", default="object", help="object | room | a dataset folder")
    p.add_argument("--format", choices=["blender", "replica", "tum"], default=None,
                   help="dataset layout (detected from the folder if left out)")
    p.add_argument("--method", choices=["vbgs", "gradient"], default="vbgs")
    p.add_argument("--components", type=int, default=20000, help="components / splat capacity")
    p.add_argument("--frames", type=int, default=60, help="training frames (at most)")
    p.add_argument("--test-views", type=int, default=8, help="held-out views (at most)")
    p.add_argument("--size", type=int, default=128, help="image size (longer side)")
    p.add_argument("--order", choices=["sequential", "shuffled", "reversed"], default="sequential")
    p.add_argument("--assign", choices=["prior", "posterior"], default="prior")
    p.add_argument("--estep", choices=["dense", "sparse"], default="sparse")
    p.add_argument("--candidates", type=int, default=16, help="components per point (sparse)")
    p.add_argument("--init", choices=INITS, default=INITS[0], help=INIT_HELP)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--opacity", type=float, default=None, help="VBGS splat opacity")
    p.add_argument("--splat-scale", type=float, default=None,
                   help="VBGS splat covariance scale (sigma multiplier)")
    p.add_argument("--replay", default="none", help="gradient: none | fifo:K | reservoir:K | full")
    p.add_argument("--steps-per-frame", type=int, default=50, help="gradient, continual")
    p.add_argument("--steps", type=int, default=3000, help="gradient, static protocol")
    p.add_argument("--protocol", choices=["continual", "static"], default="continual")
    p.add_argument("--skip-margin", type=float, default=None, metavar="NATS",
                   help="VBGS: skip points explained within NATS of their component's peak")
    p.add_argument("--depth-model", metavar="ONNX", help="estimate depth from RGB with this model")
    p.add_argument("--depth-kind", choices=["metric", "inverse", "relative"], default="inverse")
    p.add_argument("--depth-preset", default=None, help="depth model family preset")
    p.add_argument("--depth-align", default="auto",
                   help="auto | none | median | scale-shift | scale-shift-inverse")
    p.add_argument("--ply", metavar="OUT", help="save the splats as a 3DGS PLY")
    p.add_argument("--save", metavar="PNG", help="ground truth and render of held-out views")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _fit_scene(args) -> dict:
    from experiments.scene_task import SceneTask, run_scene, save_views

    render = {k: v for k, v in (("opacity", args.opacity), ("splat_scale", args.splat_scale))
              if v is not None}
    task = SceneTask(scene=args.scene, format=args.format, method=args.method,
                     components=args.components, frames=args.frames, n_test=args.test_views,
                     size=args.size, order=args.order, assign=args.assign, estep=args.estep,
                     candidates=args.candidates, init=args.init, seed=args.seed,
                     replay=args.replay, steps_per_frame=args.steps_per_frame, steps=args.steps,
                     protocol=args.protocol, depth_model=args.depth_model,
                     depth_kind=args.depth_kind, depth_preset=args.depth_preset,
                     depth_align=args.depth_align, skip_margin=args.skip_margin, **render)
    result = run_scene(task, progress=sys.stderr.isatty(), ply=args.ply)
    if args.save:
        save_views(args.save, result.images["target"], result.images["render"],
                   f"{args.scene}, {args.method}: {result.psnr:.2f} dB held-out")
    return result.to_dict(images=False)


def _add_depth_study(sub):
    p = sub.add_parser("depth-study", help="sensor vs estimated depth (ONNX test model)")
    p.add_argument("--scene", default="object")
    p.add_argument("--components", type=int, default=20000)
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--methods", nargs="+", choices=["vbgs", "gradient"],
                   default=["vbgs", "gradient"])
    p.add_argument("--steps-per-frame", type=int, default=50, help="gradient, continual")
    p.add_argument("--out", default="results/depth_study")
    p.add_argument("--json", action="store_true")


def _depth_study(args) -> dict:
    from experiments.bench import write_table
    from experiments.depth_study import run_depth_study

    rows = run_depth_study(args.out, methods=args.methods, progress=sys.stderr.isatty(),
                           scene=args.scene, components=args.components, frames=args.frames,
                           size=args.size, init="data", steps_per_frame=args.steps_per_frame)
    paths = write_table(rows, args.out, "depth_study")
    return {"rows": rows, "files": [str(p) for p in paths]}


def _add_bench(sub):
    p = sub.add_parser("bench", help="benchmarks; figures are printed and written as CSV/markdown")
    p.add_argument("target", choices=["image", "estep", "raster", "depth"],
                   help="image: CAVI per iteration; estep: dense vs sparse per frame; "
                        "raster: 3-D rasterizer; depth: ONNX adapter throughput")
    p.add_argument("--sizes", type=int, nargs="+", default=None,
                   help="image sizes (image: 64 128, raster: 128 256, estep: 128)")
    p.add_argument("--components", type=int, nargs="+", default=None,
                   help="component counts (image: 500..8000, estep: 20000 50000)")
    p.add_argument("--iters", type=int, default=3, help="timed CAVI iterations per cell")
    p.add_argument("--out", default="results/bench", help="folder for the CSV and markdown table")
    p.add_argument("--json", action="store_true")


def _bench(args) -> dict:
    from experiments import bench

    progress = sys.stderr.isatty()
    if args.target == "image":
        rows = bench.bench_image(args.sizes or [64, 128],
                                 args.components or [500, 1000, 2000, 4000, 8000],
                                 iters=args.iters, progress=progress)
    elif args.target == "estep":
        rows = bench.bench_estep(args.components or [20000, 50000],
                                 size=(args.sizes or [128])[0], progress=progress)
    elif args.target == "raster":
        from experiments.bench_raster import bench_rasterizer

        rows = bench_rasterizer(sizes=tuple(args.sizes or (128, 256)),
                                counts=tuple(args.components or (10_000, 50_000)))
    else:
        from depth.bench import bench_adapter

        rows = [bench_adapter(size=(args.sizes or [256])[0])]
    paths = bench.write_table(rows, args.out, f"bench_{args.target}")
    return {"rows": rows, "files": [str(p) for p in paths]}


COMMANDS = {"fit-image": (_add_fit_image, _fit_image), "fit-scene": (_add_fit_scene, _fit_scene),
            "depth-study": (_add_depth_study, _depth_study), "bench": (_add_bench, _bench),
            "sweep": (add_sweep, run_sweep), "report": (add_report, run_report)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.run", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    for add, _ in COMMANDS.values():
        add(sub)
    args = parser.parse_args(argv)
    try:
        result = COMMANDS[args.command][1](args)
    except (ValueError, TypeError, FileNotFoundError) as err:
        return fail(err)
    print_result(args.command, result, as_json=getattr(args, "json", False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
