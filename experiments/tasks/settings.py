"""The categorical task settings, declared once: their choices, default and help.

Read by the task dataclasses (field defaults and checks), by the CLI (argparse
``choices`` and ``default``, :func:`add_choice`) and by the sweep validation
(:data:`experiments.sweep.config.SETTINGS`), so the three cannot drift apart. The
start schemes live in :mod:`experiments.tasks.init_schemes` and are wrapped here.

Kept light to import (no JAX): the CLI builds its parsers from it before any task
module is loaded. Choices that a library module also lists (stream orders, depth
kinds, depth sensors: :mod:`vbgs.sensors` is NumPy only) are taken from that module;
the learners' and dataset formats' tables are heavier to import, and a test holds
:data:`METHOD` and :data:`FORMAT` equal to them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from depth.presets import KINDS as DEPTH_KINDS
from depth.stream import REFERENCES as DEPTH_REFERENCES
from experiments.tasks.init_schemes import INIT_HELP, INITS
from vbgs.data.streams import ORDERS
from vbgs.sensors import HOLED_SENSORS, SENSOR_HOLES, SENSOR_NAMES
from vbgs.sensors.holes import HOLE_RATE


@dataclass(frozen=True)
class Choice:
    """A setting that takes one of ``values``; ``default`` is None or one of them."""

    values: tuple[str, ...]
    default: str | None
    help: str

    def __post_init__(self):
        if self.default is not None and self.default not in self.values:
            raise ValueError(f"default {self.default!r} is not one of {self.values}")

    def check(self, name: str, value) -> None:
        """Refuse a value that is not a choice, naming the setting and the choices."""
        if value not in self.values and not (value is None and self.default is None):
            raise ValueError(f"unknown {name} {value!r}: use one of {', '.join(self.values)}")


METHOD = Choice(("vbgs", "gradient", "vbgs-polish"), "vbgs",
                "vbgs, the gradient 3DGS baseline, or vbgs-polish (VBGS, then gradient "
                "steps from its splats; scenes only)")
INIT = Choice(INITS, INITS[0], INIT_HELP)
ORDER = Choice(ORDERS, "sequential", "stream order")
ASSIGN = Choice(("prior", "posterior"), "prior",
                "responsibilities under the prior or the current posterior")
STREAM = Choice(("none", "patches"), "none", "image fit on all pixels, or a stream of patches")
ESTEP = Choice(("dense", "sparse"), "sparse", "E-step over all components, or the few nearby")
SEARCH = Choice(("auto", "kdtree", "projective"), "auto",
                "VBGS: how a frame's points find their nearby components: a KD-tree over "
                "the map's means, or by projection at the frame's pose, on the device "
                "(vbgs.inference.projective); auto: by projection for frames larger "
                "than 320x240")
FORMAT = Choice(("blender", "replica", "tum"), None,
                "dataset layout of a scene folder (detected from the folder if left out)")
PROTOCOL = Choice(("continual", "static"), "continual",
                  "continual: frames arrive one by one, once; static: every training frame "
                  "from the start, --steps steps on frames drawn uniformly (gradient, "
                  "vbgs-polish)")
OPACITY_RULE = Choice(("evidence", "constant"), "evidence",
                      "VBGS splat opacity: per component from hit/pass-through rays "
                      "(evidence) or the constant --opacity")
# The fit scores more on validation views (about a tenth of a dB over the object and the
# room, results/tuning/colour/mean.md; more on the walk, colour_walk/, and on the object
# under the Kinect, colour_kinect/) at 2.4 to 3.7 times the seconds a frame
# (results/tuning/colour_cost/, single runs on a loaded machine). Off by default: a frame's time is
# what a stream at a sensor's rate cannot spare, and turning it on would re-make every
# VBGS result.
COLOUR_RULE = Choice(("posterior", "fit"), "posterior",
                     "VBGS splat colours: the posterior colour means, or fitted to the "
                     "training pixels (fit: 0.1-0.4 dB more on validation views, at 1.6 to "
                     "4 times the time per frame)")
DEPTH_KIND = Choice(DEPTH_KINDS, "inverse", "what the depth model outputs")
DEPTH_REFERENCE = Choice(DEPTH_REFERENCES, "auto",
                         "what aligns the depth model's output to metric depth, read from "
                         "arrived frames only: views (multi-view consistency of the first "
                         "frames, with their poses), sensor (the first frame with sensor "
                         "depth), auto (sensor if the first frame has depth, else views)")
SENSOR = Choice(SENSOR_NAMES, "exact",
                "depth sensor simulated on the training frames (vbgs.sensors): exact, a "
                "kinect v1, a realsense active stereo or a mono depth network; test and "
                "validation views keep their exact depth")
MEASURED_BY = Choice(SENSOR_NAMES, None,
                     "how the training depth was measured, as the learners take it into "
                     "account (VBGS: the noise along each ray, holes that are not "
                     "background; the gradient baseline: its depth L1 weighted by 1/sigma); "
                     "exact: the depth is the surface's. Default: the data's "
                     "(vbgs.data.sensor_record: a folder's depth_sensor.json, written by "
                     "write-scene; else TUM kinect; else exact), the JSON's sensor_from")
POSES = Choice(("given", "track", "odometry"), "given",
               "training poses: given (ground truth), track (each frame registered against "
               "the map from a constant-velocity guess; the first pose given) or odometry "
               "(the guess from a drifting odometry, --drift, then registered); VBGS only")
# the simulated sensor's holes (vbgs.sensors.holes.parse_holes reads the text)
SENSOR_HOLES_DEFAULT = SENSOR_HOLES
SENSOR_HOLES_HELP = (f"holes of the simulated sensor ({', '.join(HOLED_SENSORS)}) on the "
                     "training frames: sensor (its own: edges, grazing angles, range limits and "
                     f"random dropouts at level x {HOLE_RATE:g}), none, physical (the first three), "
                     "random:RATE (random dropouts only, e.g. random:0.05, whatever the "
                     "level) or physical+random:RATE; the noise drawn is the same whatever "
                     "the holes")
DRIFT_DEFAULT = "0.01,0.5"  # --drift: metres and degrees per frame (vbgs.tracking.drift)
# --splat-scale auto: VBGS chooses the scale on the arrived training frames
# (vbgs.render.scale_fit), keeping a uniform sample of AUTO_SCALE_FRAMES of them
AUTO_SCALE = "auto"
AUTO_SCALE_FRAMES = 12


def valid_splat_scale(value) -> bool:
    """A splat scale a task takes: a positive finite number, or ``auto``."""
    if isinstance(value, str):
        return value == AUTO_SCALE
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


def splat_scale_arg(text: str) -> float | str:
    """A command line's splat scale: a number becomes a float, anything else stays text
    for the task's check to accept (``auto``) or refuse, one message either way."""
    try:
        return float(text)
    except ValueError:
        return text.strip()


REPLAY_DEFAULT = "none"  # replay specs are parsed by vbgs.baseline.replay.parse_replay
# --cl-segments with no number: the stream cut into this many segments for the
# continual-learning matrix (experiments.tasks.continual); without the flag it is not measured
CL_SEGMENTS_DEFAULT = 5


def add_choice(parser, flag: str, choice: Choice, help: str | None = None) -> None:
    """``parser.add_argument(flag)`` with the choices and default of ``choice``."""
    parser.add_argument(flag, choices=choice.values, default=choice.default,
                        help=choice.help if help is None else help)
