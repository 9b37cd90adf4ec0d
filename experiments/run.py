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

from experiments.cli import (
    bench,
    check,
    depth_study,
    diagnostics,
    fit_image,
    fit_scene,
    front,
    oracle,
    tune,
    write_scene,
)
from experiments.cli.inapplicable import given_flags, refuse_inapplicable, watched
from experiments.cli.output import fail, interrupted, meaningless_score_warning, print_result
from experiments.provenance import record_command, stamp


def _sweep_cli(name: str):
    """A function of :mod:`experiments.sweep.cli`, imported when first called (it
    imports tqdm; start-up time that other commands do not need)."""

    def call(*args):
        from experiments.sweep import cli

        return getattr(cli, name)(*args)

    return call


# each command: (add its parser, run it); one module of experiments.cli per command
COMMANDS = {"fit-image": (fit_image.add, fit_image.run),
            "fit-scene": (fit_scene.add, fit_scene.run),
            "check": (check.add, check.run),
            "write-scene": (write_scene.add, write_scene.run),
            "depth-study": (depth_study.add, depth_study.run), "bench": (bench.add, bench.run),
            "oracle": (oracle.add, oracle.run), "tune": (tune.add, tune.run),
            "colour-gap": (diagnostics.add_colour_gap, diagnostics.colour_gap),
            "render-bound": (diagnostics.add_render_bound, diagnostics.render_bound),
            "front": (front.add, front.run),
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
    except (ValueError, OSError, ImportError) as err:  # the input refused (the project raises
        # ValueError and its subclasses for bad input), a file that cannot be read or written,
        # an optional dependency a command needs that is missing: one line. Anything else
        # (a TypeError, an AttributeError ...) is a programming error and shows its traceback.
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
