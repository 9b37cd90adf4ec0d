"""``python -m experiments.run check --scene FOLDER``: the dataset doctor, and the checks
``fit-scene`` runs on a dataset folder before any work.

The checks themselves are :mod:`vbgs.data.doctor`'s; where intrinsics and depth scales
come from, :mod:`vbgs.data.calibration`'s. Here: the command's report, the task's
calibration flags, the consistency warning and the test views scored after training on
part of a trajectory.
"""

from __future__ import annotations

import sys
from pathlib import Path

from vbgs.data.calibration import check_depth_scale, check_intrinsics
from vbgs.data.doctor import examine
from vbgs.data.formats import detect_format, load_scene
from vbgs.data.scene import Scene, inside_span
from vbgs.data.doctor import folder_checks, leaked_views, pairing_fixes
from vbgs.data.synthetic import SCENES

# fit-scene's consistency check looks at this many frames (the doctor at DOCTOR_FRAMES).
FIT_FRAMES = 4
DOCTOR_FRAMES = 8


def check_calibration(task) -> None:
    """A task's ``intrinsics`` and ``depth_scale``: well formed, and for a dataset folder."""
    if task.intrinsics is None and task.depth_scale is None:
        return
    if task.scene in SCENES and not Path(task.scene).is_dir():
        raise ValueError(f"--intrinsics and --depth-scale apply to dataset folders; "
                         f"{task.scene!r} is a synthetic scene with exact cameras and depth")
    if task.intrinsics is not None:
        check_intrinsics(task.intrinsics)
    if task.depth_scale is not None:
        check_depth_scale(task.depth_scale)


def within_trained_span(scene: Scene, frames: int) -> Scene:
    """With fewer training frames than the folder holds, only the test views whose camera
    lies within the trained part of the trajectory (:func:`vbgs.data.scene.inside_span`):
    the others show ground never seen. Says on stderr how many were left out, and the
    record carries the count; none left is refused."""
    train = scene.train[:frames]
    if len(train) == len(scene.train) or not scene.test:
        return scene
    keep = inside_span(train, scene.test)
    outside = int((~keep).sum())
    if not outside:
        return scene
    if outside == len(scene.test):
        raise ValueError(f"--frames {frames}: none of the {len(scene.test)} test views lies "
                         f"near the {len(train)} trained frames (of {len(scene.train)}), so "
                         f"no score would measure what was learned; give more --frames")
    print(f"note: --frames {frames} trains on {len(train)} of {len(scene.train)} frames; "
          f"{outside} of {len(scene.test)} test views lie outside the span they cover and "
          f"are not scored", file=sys.stderr)
    return scene._replace(test=[f for f, k in zip(scene.test, keep, strict=True) if k],
                          record={**scene.record, "test_views_outside_span": outside})


# Frames narrower or shorter than this many pixels hold too few pixels for a score to mean
# anything (a 1x1 frame is one colour: any splat matches it).
MIN_SIDE = 8


def warn_tiny_frames(scene: Scene, where: str) -> None:
    """Say on stderr when the frames are under MIN_SIDE pixels on a side."""
    cam = scene.train[0].camera
    if min(cam.width, cam.height) < MIN_SIDE:
        print(f"warning: scene {where!r}: frames of {cam.width}x{cam.height} pixels: a score "
              f"over so few pixels measures next to nothing (a 1x1 frame is one colour); "
              f"give a --size of at least {MIN_SIDE}", file=sys.stderr)


def folder_findings(scene: Scene, where: str) -> Scene:
    """A folder's own checks (:func:`vbgs.data.doctor.folder_checks`) before fit-scene's work:
    intrinsics for another aspect and frozen depth refused; test views bit-identical to a
    training frame left out of the scores (none left: refused); duplicate frames and rgb
    images left out in pairing said on stderr."""
    more = f"`python -m experiments.run check --scene {where}` says more"
    for check in folder_checks(scene):
        if check.ok is not False:
            continue
        if check.name in ("camera size", "frozen depth"):
            raise ValueError(f"scene {where!r}: {check.name}: {check.message}; {more}")
        print(f"warning: {check.name}: {check.message} ({more})", file=sys.stderr)
    leaked = leaked_views(scene.train, scene.test)
    if leaked.all() and len(leaked):
        raise ValueError(f"scene {where!r}: every one of the {len(leaked)} test views is "
                         f"bit-identical to a training frame, so no score would measure "
                         f"what was learned; {more}")
    if leaked.any():
        print(f"note: {int(leaked.sum())} of {len(leaked)} test views are bit-identical to a "
              f"training frame and are not scored", file=sys.stderr)
        scene = scene._replace(test=[f for f, k in zip(scene.test, leaked, strict=True)
                                     if not k],
                               record={**scene.record, "test_views_leaked": int(leaked.sum())})
    return scene


def tum_reload(scene: str, format: str | None, size, given: dict, frames: int | None):
    """``depth_delay -> training frames`` of a TUM folder loaded as ``scene`` was (the
    doctor's re-pairing fixes); None for other formats."""
    if format != "tum":
        return None
    return lambda delay: load_scene(scene, format=format, size=size, depth_delay=delay,
                                    **given).train[:frames]


def warn_inconsistent(scene: Scene, format: str | None, where: str, reload=None) -> None:
    """Say on stderr when a few training frames' depth does not agree across views,
    naming the fix that makes it agree when one does."""
    extra = pairing_fixes(scene.record, reload) if reload else ()
    report = examine(scene.train, format, scene.record.get("depth_scale"), FIT_FRAMES, extra)
    check = report.checks[-1]
    if check.ok is False:
        fix = f"; likely: {report.fix_words}" if report.fix else ""
        print(f"warning: consistency: {check.message}{fix} (`python -m experiments.run check "
              f"--scene {where}` says more)", file=sys.stderr)


def check_scene(scene: str, format: str | None = None, size: int | None = 128,
                frames: int | None = None, intrinsics=None, depth_scale=None) -> dict:
    """The doctor's report on a scene loaded as fit-scene loads it: every check
    (``rows``), ``healthy``, the views' agreement, the fix named when one makes them
    agree, the intrinsics and depth scale used and where they came from, and ``error``
    (the first failure in one line) when unhealthy. Load failures raise ValueError."""
    given = {k: v for k, v in (("intrinsics", intrinsics), ("depth_scale", depth_scale))
             if v is not None}
    folder = Path(scene).is_dir()
    if given and not folder:
        raise ValueError(f"--intrinsics and --depth-scale apply to dataset folders; {scene!r} "
                         f"is not one")
    format = format or (detect_format(scene) if folder else None)
    loaded = load_scene(scene, format=format, size=size, **given)
    train = loaded.train[:frames]
    reload = tum_reload(scene, format, size, given, frames)
    extra = pairing_fixes(loaded.record, reload) if reload else ()
    before = folder_checks(loaded._replace(train=train)) if folder else ()
    report = examine(train, format, loaded.record.get("depth_scale"), DOCTOR_FRAMES, extra,
                     tuple(before))
    cam = train[0].camera
    out = {"scene": scene, "format": format or "synthetic", "frames": len(train),
           "healthy": report.healthy, "agreement": report.agreement,
           "expected_agreement": report.expected, "fix": report.fix,
           "fix_words": report.fix_words, "fix_agreement": report.fix_agreement,
           "intrinsics": [float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy)],
           "image_size": [int(cam.width), int(cam.height)], **loaded.record,
           "rows": [{"check": c.name, "ok": c.ok, "message": c.message,
                     "frames": ",".join(map(str, c.frames[:12]))} for c in report.checks]}
    failed = [c for c in report.checks if c.ok is False]
    if failed:
        fix = f"; likely fix: {report.fix_words}" if report.fix else ""
        out["error"] = f"{failed[0].name}: {failed[0].message}{fix}"
    return out
