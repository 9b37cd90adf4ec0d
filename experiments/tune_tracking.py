"""Tracking settings checked on validation trajectories.

    python -m experiments.tune_tracking [--seeds 1 2] [--variants NAME ...] --out DIR

runs the tracked streams of the tracking study (``experiments/configs/tracking.toml``:
``--poses track`` on the object, the room and the walk with exact depth and under a
simulated Kinect, ``--poses odometry`` on the room and the walk) on trajectories of their
own: the scenes' other seeds, whose camera paths start elsewhere (another phase of the
object's orbit, of the room's loop, of the walk's wander) through jittered furniture.
Seed 0, the trajectories the tracking table reports, is refused. Each ``VARIANTS`` entry
moves one tracking setting from its default; every run is its own process (the settings
are read when the tracker compiles) and scores the ATE RMSE against the true poses, no
view. ``DIR/tracking.md`` and ``.csv`` hold one row per variant, the ATE (mm) of each
stream and their sum; the markdown names the command and the code version.
"""

from __future__ import annotations

import argparse
import functools
import json
import subprocess
import sys
import time
from pathlib import Path

# The tracked streams of the tracking study: (scene, poses, sensor).
STREAMS = tuple((s, "track", d) for s in ("object", "room", "walk") for d in ("exact", "kinect")) \
    + (("room", "odometry", "exact"), ("walk", "odometry", "exact"), ("walk", "odometry", "kinect"))


def _after_direct(points: int, iterations: int) -> None:
    import experiments.tasks.tracking as tracking

    tracking.AFTER_DIRECT = {**tracking.AFTER_DIRECT, "levels": (points,),
                             "iterations": iterations}


def _direct_iterations(iterations: tuple[int, ...]) -> None:
    from vbgs.tracking import direct

    direct.DirectConfig = functools.partial(direct.DirectConfig, iterations=iterations)


def _floor_d(value: float) -> None:
    from vbgs.tracking import direct

    direct.FLOOR_D = value


def _ratio(value: float) -> None:
    from vbgs.tracking import register

    register.directions = functools.partial(register.directions, ratio=value)


# name -> (what it moves, the patch applied in the run's process before anything compiles)
VARIANTS = {
    "default": ("the defaults", lambda: None),
    "after_direct=1024x4": ("experiments.tasks.tracking.AFTER_DIRECT: 1024 points, 4 steps "
                            "(default 2048, 6)", lambda: _after_direct(1024, 4)),
    "direct.iterations=10,8,6": ("vbgs.tracking.direct.ITERATIONS (default 6, 4, 3)",
                                 lambda: _direct_iterations((10, 8, 6))),
    "direct.floor_d=0.0043": ("vbgs.tracking.direct.FLOOR_D, a share of the median inverse "
                              "depth (default 0.013; 0.0043 is 1e-3 per unit on the walk)",
                              lambda: _floor_d(0.0043)),
    "degeneracy.ratio=3e-3": ("vbgs.tracking.degeneracy.RATIO (default 1e-2)",
                              lambda: _ratio(3e-3)),
}


def stream_argv(scene: str, poses: str, sensor: str, seed: int, size: int, frames: int,
                components: int) -> list[str]:
    """fit-scene's words for one tracked stream."""
    return ["fit-scene", "--scene", scene, "--poses", poses, "--simulate-sensor", sensor,
            "--sensor", sensor, "--seed", str(seed), "--size", str(size), "--frames",
            str(frames), "--components", str(components), "--test-views", "1", "--json"]


def run_one(variant: str, argv: list[str]) -> dict:
    """One fit-scene run under ``variant``, in a process of its own; its JSON record."""
    out = subprocess.run([sys.executable, "-m", "experiments.tune_tracking", "--one", variant,
                          "--", *argv], capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"{variant} {' '.join(argv)} failed: {out.stderr.strip()[-500:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _one(variant: str, argv: list[str]) -> int:
    from experiments.run import main as run_main

    VARIANTS[variant][1]()
    return run_main(argv)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--one"]:
        return _one(argv[1], argv[3:])
    parser = argparse.ArgumentParser(prog="python -m experiments.tune_tracking",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--components", type=int, default=20000)
    parser.add_argument("--out", default="runs/tuning/tracking")
    args = parser.parse_args(argv)
    if 0 in args.seeds:
        parser.error("seed 0 is the trajectories the tracking table reports: validate on "
                     "other seeds")
    from experiments.provenance import record_command

    record_command(argv, parser.prog)
    rows = []
    for variant in args.variants:
        row = {"variant": variant, "moves": VARIANTS[variant][0]}
        start = time.perf_counter()
        for seed in args.seeds:
            for scene, poses, sensor in STREAMS:
                record = run_one(variant, stream_argv(scene, poses, sensor, seed, args.size,
                                                      args.frames, args.components))
                row[f"{scene} {poses} {sensor} s{seed}"] = 1e3 * record["ate_rmse"]
                print(f"{variant} seed {seed} {scene} {poses} {sensor}: "
                      f"{1e3 * record['ate_rmse']:.3f} mm", file=sys.stderr, flush=True)
        row["sum"] = sum(v for k, v in row.items() if k.endswith(tuple(f" s{s}"
                                                                       for s in args.seeds)))
        row["wall s"] = time.perf_counter() - start
        rows.append(row)
        files = write_table(rows, Path(args.out), args)  # after each row: a stop keeps them
    print(json.dumps({"rows": rows, "files": [str(f) for f in files]}))
    return 0


def write_table(rows: list[dict], out: Path, args) -> list[Path]:
    """``tracking.csv`` and ``tracking.md`` under ``out``, the markdown headed by the
    command and the code version."""
    import pandas as pd

    from experiments.benchmarks.bench import machine
    from experiments.provenance import first_line
    from vbgs.io_atomic import write_atomic, write_text_atomic

    out.mkdir(parents=True, exist_ok=True)
    frame = pd.DataFrame(rows)
    csv, md = out / "tracking.csv", out / "tracking.md"
    write_atomic(csv, lambda tmp: frame.to_csv(tmp, index=False))
    about = (f"ATE RMSE (mm) against the true poses of each tracked stream on validation "
             f"trajectories (seeds {', '.join(map(str, args.seeds))}; the tracking table "
             f"reports seed 0), {args.size} px, {args.frames} frames, {args.components} "
             f"components; one setting moved a row. `wall s`: the row's runs, compilation "
             f"included, on a shared machine.")
    write_text_atomic(md, f"{first_line()}\n\n# Tracking settings on validation "
                          f"trajectories\n\n{about}\n\nMeasured on: {machine()}\n\n"
                          f"{frame.to_markdown(index=False, floatfmt='.3f')}\n")
    return [csv, md]


if __name__ == "__main__":
    sys.exit(main())
