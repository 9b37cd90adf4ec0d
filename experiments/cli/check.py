"""``check``: a dataset doctor for a folder (cameras, depth scale, multi-view consistency)."""

from __future__ import annotations

from experiments.cli.options import add_calibration, add_json, calibration
from experiments.tasks.settings import FORMAT, add_choice


def add(sub):
    p = sub.add_parser("check", help="a dataset doctor: rotations, intrinsics, depth scale and "
                                     "multi-view consistency; names the likely fix (exit 2 "
                                     "when a check fails)")
    p.add_argument("--scene", required=True, help="a dataset folder (or a synthetic scene name)")
    add_choice(p, "--format", FORMAT)
    p.add_argument("--size", type=int, default=128, help="image size (longer side; 0: keep)")
    p.add_argument("--frames", type=int, default=None, help="training frames (default: all)")
    add_calibration(p)
    add_json(p)


def run(args) -> dict:
    from experiments.tasks.check import check_scene

    if args.size < 0 or (args.frames is not None and args.frames < 1):
        raise ValueError(f"--size must be >= 0 and --frames >= 1, got {args.size} and "
                         f"{args.frames}")
    return check_scene(args.scene, args.format, args.size or None, args.frames,
                       **calibration(args))
