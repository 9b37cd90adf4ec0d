"""``python -m experiments.run COMMAND ...``: fits, benchmarks, sweeps and reports.

Commands:
  fit-image   fit one photo (batch CAVI or a patch stream) and score it
  bench       benchmarks (``bench image``)
"""

from __future__ import annotations

import argparse
import sys

from experiments.cli_common import fail, print_result
from experiments.sweep.cli import add_report, add_sweep, run_report, run_sweep


def _add_fit_image(sub):
    p = sub.add_parser("fit-image", help="fit one photo with VBGS and report PSNR/SSIM")
    p.add_argument("--image", default="astronaut", help="bundled photo name or image file path")
    p.add_argument("--size", type=int, default=64, help="resize to SIZE x SIZE (0: keep)")
    p.add_argument("--components", type=int, default=2000)
    p.add_argument("--iters", type=int, default=10, help="CAVI iterations (batch fits)")
    p.add_argument("--init", choices=["random", "data"], default="data")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--stream", choices=["none", "patches"], default="none")
    p.add_argument("--order", choices=["sequential", "shuffled", "reversed"], default="sequential")
    p.add_argument("--assign", choices=["prior", "posterior"], default="prior")
    p.add_argument("--patch", type=int, default=8, help="patch side for --stream patches")
    p.add_argument("--reassign", choices=["on", "off", "auto"], default="auto",
                   help="re-seed unused components (auto: on for batch fits, off for streams)")
    p.add_argument("--save", metavar="PNG", help="write target, render and error side by side")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def _fit_image(args) -> dict:
    from experiments.image_task import ImageTask, run_image, save_comparison

    reassign = {"on": True, "off": False, "auto": args.stream == "none"}[args.reassign]
    task = ImageTask(image=args.image, size=args.size or None, components=args.components,
                     iters=args.iters, init=args.init, seed=args.seed, stream=args.stream,
                     order=args.order, assign=args.assign, patch=args.patch, reassign=reassign)
    result = run_image(task, progress=sys.stderr.isatty())
    images = result.pop("images")
    if args.save:
        save_comparison(args.save, images["target"], images["render"],
                        f"{args.image}: {result['psnr']:.2f} dB, {args.components} components")
    return result


def _add_bench(sub):
    p = sub.add_parser("bench", help="benchmarks; figures are printed and written as CSV/markdown")
    p.add_argument("target", choices=["image"], help="what to benchmark")
    p.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    p.add_argument("--components", type=int, nargs="+", default=[500, 1000, 2000, 4000, 8000])
    p.add_argument("--iters", type=int, default=3, help="timed CAVI iterations per cell")
    p.add_argument("--out", default="results/bench", help="folder for the CSV and markdown table")
    p.add_argument("--json", action="store_true")


def _bench(args) -> dict:
    from experiments.bench import bench_image, write_table

    rows = bench_image(args.sizes, args.components, iters=args.iters,
                       progress=sys.stderr.isatty())
    paths = write_table(rows, args.out, f"bench_{args.target}")
    return {"rows": rows, "files": [str(p) for p in paths]}


COMMANDS = {"fit-image": (_add_fit_image, _fit_image), "bench": (_add_bench, _bench),
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
