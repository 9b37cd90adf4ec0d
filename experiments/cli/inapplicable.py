"""Flags that do not apply to what runs: refused in one line naming why, instead of
accepted and ignored (the summary would echo a setting that never ran).

Whether a flag was given is read off the command line (:func:`given_flags`), not off
its value: ``--protocol continual`` given with VBGS is harmless, ``--protocol static``
is not, and ``--opacity 0.9`` equal to a default is still a request.
"""

from __future__ import annotations

import argparse

_UNSET = object()

# (dest, the flag, applies when, why not otherwise); `when` reads the parsed args.
_VBGS_STREAMS = ("VBGS learns each frame once by a conjugate update: it takes no optimiser "
                 "steps and keeps no replay buffer")
_STEPPED = ("gradient", "vbgs-polish")  # the methods that take optimiser steps
_FOR_STEPPED = "applies to the gradient baseline and vbgs-polish (--method gradient | vbgs-polish)"

def _noisy_sensor(a) -> bool:
    """A noisy sensor is simulated, learned under, or measured the folder's depth (its
    record); a malformed level counts as applying (it is refused with its own message)."""
    from vbgs.data.sensor_record import data_sensor
    from vbgs.sensors import check_level

    try:
        check_level(a.sensor_level)
    except ValueError:
        return True
    if a.simulate_sensor != "exact":
        return True
    if a.sensor is not None:
        return a.sensor != "exact"
    try:
        return data_sensor(a.scene, a.format).sensor != "exact"
    except ValueError:  # a malformed record is refused when the task reads it
        return True


_SENSOR_LEVEL = ("sensor_level", "--sensor-level", _noisy_sensor,
                 "scales a sensor's noise, but no noisy sensor is simulated (--simulate-sensor "
                 "exact) or learned under (--sensor exact, this scene's own); give "
                 "--simulate-sensor or --sensor kinect|realsense|mono with it, or drop it")

_VBGS_MAP = ("is a setting of --method vbgs's map; the gradient baseline and vbgs-polish "
             "keep none: drop it")

RULES = {
    "fit-scene": (
        ("replay", "--replay", lambda a: a.method in _STEPPED,
         f"{_FOR_STEPPED}; {_VBGS_STREAMS}"),
        ("steps_per_frame", "--steps-per-frame", lambda a: a.method in _STEPPED,
         f"{_FOR_STEPPED}; {_VBGS_STREAMS}"),
        ("steps", "--steps", lambda a: a.method in _STEPPED,
         f"{_FOR_STEPPED} under --protocol static; {_VBGS_STREAMS}"),
        ("protocol", "--protocol static", lambda a: a.method in _STEPPED or
         a.protocol != "static", f"{_FOR_STEPPED}; VBGS always streams, each frame once"),
        ("cl_segments", "--cl-segments", lambda a: a.method not in _STEPPED or
         a.protocol != "static", "measures the matrix along a stream of frames; --protocol "
         "static has none (every frame from the start)"),
        ("budget_points", "--budget-points", lambda a: a.method != "gradient",
         "thins the frames VBGS learns (vbgs.mapping.budget); the gradient baseline samples "
         "its own pixels each step"),
        ("budget_saturation", "--budget-saturation", lambda a: a.method != "gradient",
         "skips points of cells VBGS has learned often (vbgs.mapping.saturation); the "
         "gradient baseline samples its own pixels each step"),
        ("opacity", "--opacity", lambda a: a.opacity_rule == "constant",
         "sets the opacity of --opacity-rule constant; under the default rule (evidence) each "
         "splat's opacity comes from the rays that hit or pass it; add --opacity-rule constant"),
        ("depth_kind", "--depth-kind", lambda a: bool(a.depth_model),
         "describes the output of --depth-model ONNX; without a model the folder's own depth "
         "is used"),
        ("depth_preset", "--depth-preset", lambda a: bool(a.depth_model),
         "names the family of --depth-model ONNX; without a model the folder's own depth is "
         "used"),
        ("depth_align", "--depth-align", lambda a: bool(a.depth_model),
         "aligns the depth of --depth-model ONNX; without a model the folder's own depth is "
         "used"),
        ("depth_reference", "--depth-reference", lambda a: bool(a.depth_model),
         "says what aligns the depth of --depth-model ONNX; without a model the folder's own "
         "depth is used"),
        ("drift", "--drift", lambda a: a.poses == "odometry",
         "sets the error of the simulated odometry of --poses odometry; with --poses "
         "given or track there is none"),
        *((dest, flag, lambda a: a.method == "vbgs", _VBGS_MAP)
          for dest, flag in (("search", "--search"), ("save_map", "--save-map"),
                             ("resume_map", "--resume-map"), ("stage_times", "--stage-times"),
                             ("streaming_bound", "--streaming-bound"),
                             ("forget_after", "--forget-after"),
                             ("recolour_sigmas", "--recolour-sigmas"),
                             ("recolour_reference", "--recolour-reference"),
                             ("recolour_gate", "--recolour-gate"),
                             ("doubt_opacity", "--doubt-opacity"),
                             ("hold_seeds", "--hold-seeds"), ("hold_paid", "--hold-paid"),
                             ("merge_ahead", "--merge-ahead"),
                             ("spent_levels", "--spent-levels"),
                             ("through_background", "--[no-]through-background"))),
        _SENSOR_LEVEL,
    ),
    "tune": (_SENSOR_LEVEL,),
}



def given_flags(parser: argparse.ArgumentParser, argv: list[str], dests) -> set[str]:
    """Which of ``dests`` the command line ``argv`` gives (argparse fills only the
    attributes a namespace lacks with their defaults, so preset ones stay unset)."""
    probe = parser.parse_args(argv, namespace=argparse.Namespace(**dict.fromkeys(dests, _UNSET)))
    return {d for d in dests if getattr(probe, d) is not _UNSET}


def refuse_inapplicable(command: str, args, given: set[str]) -> None:
    """Raise ValueError on the first given flag that does not apply, saying why."""
    for dest, flag, applies, why in RULES.get(command, ()):
        if dest in given and not applies(args):
            raise ValueError(f"{flag} {why}")


def watched(command: str) -> tuple[str, ...]:
    """The destinations whose presence :func:`refuse_inapplicable` needs for ``command``."""
    return tuple(dest for dest, *_ in RULES.get(command, ()))
