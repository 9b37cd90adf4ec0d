"""``write-scene``: a synthetic scene written as a dataset folder, a simulated sensor's
depth on its training frames (fit-scene --scene FOLDER takes that sensor by default)."""

from __future__ import annotations

from experiments.cli.options import (
    add_frames,
    add_json,
    add_scene_size,
    add_simulated_sensor,
    add_test_views,
    add_val_views,
)
from vbgs.data.scene_names import SYNTHETIC

WRITE_FORMATS = ("blender",)  # the layouts with separate train, test and val splits


def add(sub):
    p = sub.add_parser("write-scene", help="write a synthetic scene as a dataset folder, a "
                                           "simulated sensor's depth on its training frames")
    p.add_argument("--scene", default="object", help=f"a synthetic scene: {', '.join(SYNTHETIC)}")
    add_scene_size(p)
    add_frames(p, help="training frames")
    add_test_views(p)
    add_val_views(p, help="validation views")
    p.add_argument("--seed", type=int, default=0,
                   help="the scene's views and the sensor's noise, as fit-scene --seed")
    add_simulated_sensor(p, None, "noise multiplier of the simulated sensor (0: exact depth "
                         "values, 1: the published model (default), 2: twice its noise)")
    p.add_argument("--format", choices=WRITE_FORMATS, default=WRITE_FORMATS[0],
                   help="dataset layout (blender: train, test and val splits)")
    p.add_argument("--out", required=True, metavar="FOLDER", help="the folder to write")
    p.add_argument("--force", action="store_true", help="write into a non-empty --out")
    add_json(p)


def run(args) -> dict:
    from experiments.tasks.write_scene import write_scene

    return write_scene(args.scene, args.out, size=args.size, frames=args.frames,
                       n_test=args.test_views, n_val=args.val_views, seed=args.seed,
                       sensor=args.simulate_sensor, level=args.sensor_level,
                       holes=args.sensor_holes, format=args.format, force=args.force,
                       progress=True)
