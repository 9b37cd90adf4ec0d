"""Options that several commands share, each declared once here: a command's module calls
the ``add_*`` function instead of repeating the flag, its default and its help."""

from __future__ import annotations

from experiments.cli.output import SIZE_HELP, size_arg
from experiments.tasks.settings import (
    MEASURED_BY,
    SENSOR,
    SENSOR_HOLES_DEFAULT,
    SENSOR_HOLES_HELP,
)
from vbgs.data.scene_names import REAL, SYNTHETIC

SCENE_HELP = f"a built-in scene ({', '.join([*SYNTHETIC, *REAL])}) or a dataset folder"


def add_json(p) -> None:
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def add_seed(p, help: str | None = None) -> None:
    p.add_argument("--seed", type=int, default=0, help=help)


def add_scene(p, help: str = SCENE_HELP) -> None:
    p.add_argument("--scene", default="object", help=help)


def add_frames(p, default: int = 60, help: str = "training frames (at most)") -> None:
    p.add_argument("--frames", type=int, default=default, help=help)


def add_test_views(p) -> None:
    p.add_argument("--test-views", type=int, default=8, help="held-out test views (at most)")


def add_val_views(p, help: str = "validation views (at most)") -> None:
    p.add_argument("--val-views", type=int, default=4, help=help)


def add_scene_size(p) -> None:
    """A scene's frame size: one number or WIDTHxHEIGHT (:func:`size_arg`)."""
    p.add_argument("--size", type=size_arg, default=128, help=SIZE_HELP)


def add_simulated_sensor(p, level_default: float | None, level_help: str) -> None:
    """The sensor simulated on the training frames: its name, noise level and holes."""
    # checked by SceneTask, not argparse: a bad name is refused in one line
    p.add_argument("--simulate-sensor", default=SENSOR.default,
                   metavar="{" + ",".join(SENSOR.values) + "}", help=SENSOR.help)
    p.add_argument("--sensor-level", type=float, default=level_default, metavar="X",
                   help=level_help)
    p.add_argument("--sensor-holes", default=SENSOR_HOLES_DEFAULT, metavar="SPEC",
                   help=SENSOR_HOLES_HELP)


def add_sensor(p) -> None:
    """The depth sensor a scene task simulates on its training frames and learns under
    (fit-scene, tune)."""
    add_simulated_sensor(p, None, "noise multiplier of the sensor, simulated "
                         "(--simulate-sensor) and as the learner takes it (--sensor): 0: "
                         "exact depth values, 1: the published model, 2: twice its noise "
                         "(default: the folder's record of its sensor, else 1)")
    p.add_argument("--sensor", default=MEASURED_BY.default,
                   metavar="{" + ",".join(MEASURED_BY.values) + "}", help=MEASURED_BY.help)


def sensor_argv(args) -> list[str]:
    """The sensor options of ``args`` (:func:`add_sensor`) that are not the defaults, as
    command-line words."""
    words = []
    for flag, value, default in (("--simulate-sensor", args.simulate_sensor, SENSOR.default),
                                 ("--sensor", args.sensor, MEASURED_BY.default),
                                 ("--sensor-level", args.sensor_level, None),
                                 ("--sensor-holes", args.sensor_holes, SENSOR_HOLES_DEFAULT)):
        if value != default:
            words += [flag, str(value)]
    return words


def add_calibration(p) -> None:
    p.add_argument("--intrinsics", metavar="FX,FY,CX,CY", default=None,
                   help="a dataset folder's camera in pixels of its images as stored, pixel "
                        "centres at integers (default: the folder's, else the format's)")
    p.add_argument("--depth-scale", type=float, default=None, metavar="S",
                   help="depth PNG codes per scene unit (1000: millimetres; default: the "
                        "folder's, else the format's)")


def calibration(args) -> dict:
    from vbgs.data.calibration import check_depth_scale, check_intrinsics

    out = {}
    if args.intrinsics is not None:
        out["intrinsics"] = tuple(check_intrinsics(args.intrinsics))[:4]
    if args.depth_scale is not None:
        out["depth_scale"] = check_depth_scale(args.depth_scale)
    return out
