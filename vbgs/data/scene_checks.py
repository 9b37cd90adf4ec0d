"""A dataset folder's own checks, before its views are compared (:mod:`vbgs.data.doctor`):
what a list file or a calibration file can get wrong while every frame still loads.

* **duplicates**: bit-identical images or poses among the training frames (a list naming
  each frame twice, a still camera), and test or validation views bit-identical to a
  training frame: a leak, the score then measures memory;
* **frozen depth**: one depth map given to frames whose cameras differ (a ``depth.txt``
  naming the same file on every line);
* **pairing** (TUM RGB-D): rgb images left out for want of a depth image or a pose within
  the association's 0.02 s (``groundtruth.txt`` covering part of the sequence);
* **camera size**: intrinsics written for images of another aspect ratio (a
  ``cam_params.json`` for 640x480 applied to 1200x680: non-square pixels).

Each returns a :class:`~vbgs.data.doctor.Check`; :func:`folder_checks` runs them all on a
loaded :class:`~vbgs.data.scene.Scene` (the loaders' record carries the pairing and the
sizes). :func:`leaked_views` is what ``fit-scene`` leaves out of its scores.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable

import numpy as np

from vbgs.data.doctor import Check, Fix, camera_step
from vbgs.data.scene import Frame, Scene

# A camera this far (in median camera steps) from another is elsewhere: one depth map for
# both is frozen depth, not a still camera.
MOVED_STEPS = 0.5
# Intrinsics rescaled by factors whose ratio differs from 1 by more than this were
# written for images of another aspect ratio (rounding of a resize stays well inside).
ASPECT_TOLERANCE = 0.02
# A TUM sequence losing more than this share of its rgb images in pairing fails the check.
MAX_UNPAIRED = 0.1


def _digest(array: np.ndarray) -> str:
    return hashlib.sha1(np.ascontiguousarray(array).tobytes()).hexdigest()


def _groups(keys: list[str]) -> list[list[int]]:
    """Indices sharing a key, groups of two or more, in order of first appearance."""
    seen: dict[str, list[int]] = {}
    for i, k in enumerate(keys):
        seen.setdefault(k, []).append(i)
    return [g for g in seen.values() if len(g) > 1]


def leaked_views(train: list[Frame], views: list[Frame]) -> np.ndarray:
    """Mask ``[len(views)]``: which views' images are bit-identical to a training frame's."""
    seen = {_digest(f.rgb) for f in train}
    return np.array([_digest(f.rgb) in seen for f in views], bool)


def check_duplicates(scene: Scene) -> Check:
    """Bit-identical images or poses among the training frames, and held-out views
    bit-identical to a training frame."""
    images = _groups([_digest(f.rgb) for f in scene.train])
    poses = _groups([_digest(np.asarray(f.camera.pose, np.float64)) for f in scene.train])
    leaks = {split: int(leaked_views(scene.train, views).sum())
             for split, views in (("test", scene.test), ("validation", scene.val)) if views}
    said = []
    if any(leaks.values()):
        said.append(" and ".join(f"{n} of {len(scene.test if s == 'test' else scene.val)} "
                                 f"{s} views" for s, n in leaks.items() if n)
                    + " are bit-identical to a training frame (a leak: their scores would "
                      "measure memory, not the model)")
    if images:
        n = sum(len(g) for g in images)
        said.append(f"{n} of {len(scene.train)} training images are bit-identical to another "
                    f"(frames {', '.join('=' .join(map(str, g)) for g in images[:3])})")
    if poses:
        n = sum(len(g) for g in poses)
        said.append(f"{n} of {len(scene.train)} training poses are bit-identical to another")
    if not said:
        return Check("duplicates", True, f"{len(scene.train)} training images and poses "
                     f"distinct, no held-out view among them")
    still = len(images) == 1 and len(images[0]) == len(scene.train)
    cause = ("every frame is the same image: a still camera teaches one view" if still else
             "does a list file (rgb.txt, traj.txt, transforms_*.json) name frames twice?")
    frames = tuple(i for g in images for i in g[1:])
    return Check("duplicates", False, f"{'; '.join(said)}: {cause}", frames)


def check_frozen_depth(frames: list[Frame]) -> Check:
    """One depth map given to frames whose cameras are apart (more than MOVED_STEPS
    median camera steps)."""
    groups = _groups([_digest(f.depth) for f in frames])
    step = camera_step(frames) if len(frames) > 1 else 0.0
    frozen = []
    for g in groups:
        if not np.any(frames[g[0]].depth > 0):
            continue  # no depth at all (RGB-only frames): nothing frozen
        centres = np.stack([frames[i].camera.position for i in g])
        if step > 0 and np.ptp(centres, axis=0).max() > MOVED_STEPS * step:
            frozen.append(g)
    if not frozen:
        return Check("frozen depth", True, "no depth map repeats while the camera moves")
    n = sum(len(g) for g in frozen)
    return Check("frozen depth", False,
                 f"{n} of {len(frames)} frames share a bit-identical depth map while their "
                 f"cameras move (frames {', '.join('='.join(map(str, g[:4])) for g in frozen[:3])}"
                 f"): the depth list names one file for several frames, or the depth stream "
                 f"froze", tuple(i for g in frozen for i in g[1:]))


def check_pairing(record: dict) -> Check:
    """A TUM folder's pairing (:func:`vbgs.data.formats.pairing_record`): rgb images left
    out for want of a pose or a depth image, and depth files paired with several images."""
    p = record.get("pairing")
    if not p:
        return Check("pairing", None, "one file per frame: nothing to pair")
    listed, paired = p["rgb_listed"], p["rgb_paired"]
    words = (f"{paired} of {listed} rgb images paired with a depth image and a pose, each "
             f"the nearest within {p['max_time_diff']:g} s")
    lost = []
    if p["rgb_without_pose"]:
        lo, hi = p["pose_span"]
        lost.append(f"{p['rgb_without_pose']} have no pose (groundtruth.txt covers "
                    f"{lo:.3f}-{hi:.3f} s of the images' {p['rgb_span'][0]:.3f}-"
                    f"{p['rgb_span'][1]:.3f} s)")
    if p["rgb_without_depth"]:
        lost.append(f"{p['rgb_without_depth']} have no depth image that near (are depth.txt's "
                    f"stamps offset from rgb.txt's?)")
    name, uses = p["depth_file_most_reused"]
    if uses > 1 and uses >= max(3, paired // 4):
        return Check("pairing", False, f"{words}; {name} is paired with {uses} of them: "
                     f"frozen depth (does depth.txt name one file on many lines?)")
    if lost and listed - paired > MAX_UNPAIRED * listed:
        return Check("pairing", False, f"{words}; {' and '.join(lost)}: those are left out")
    return Check("pairing", True, words + (f"; {' and '.join(lost)}" if lost else ""))


def check_camera_size(record: dict) -> Check:
    """Intrinsics written for images of another aspect ratio than the images have (the
    loaders' record: ``intrinsics_for`` and ``images_stored``)."""
    if "intrinsics_for" not in record:
        return Check("camera size", None, "the intrinsics name no image size")
    (w, h), (width, height) = record["intrinsics_for"], record["images_stored"]
    source = record.get("intrinsics_from", "the intrinsics")
    sx, sy = width / w, height / h
    if abs(sx / sy - 1) > ASPECT_TOLERANCE:
        return Check("camera size", False,
                     f"{source} describes {w}x{h} images (aspect {w / h:.3f}) and these are "
                     f"{width}x{height} ({width / height:.3f}): scaled to them its pixels "
                     f"would be {sx / sy:.3f} x wider than tall; the intrinsics are another "
                     f"camera's: give this camera's with --intrinsics fx,fy,cx,cy")
    if (w, h) != (width, height):
        return Check("camera size", True, f"{source} describes {w}x{h} images, rescaled "
                     f"x{sx:.4g} to these {width}x{height} (same aspect)")
    return Check("camera size", True, f"{source} describes these {w}x{h} images")


def pairing_fixes(record: dict, reload: Callable[[float], list[Frame]]) -> tuple[Fix, ...]:
    """A TUM folder's depth paired one frame later and one frame earlier: candidate fixes
    for :func:`vbgs.data.doctor.examine`, ``reload(depth_delay)`` giving the frames loaded
    with ``depth_delay`` seconds taken off depth.txt's stamps."""
    p = record.get("pairing")
    if not p or not p.get("frame_period"):
        return ()
    period = p["frame_period"]
    out = []
    for sign, side in ((1, "late"), (-1, "early")):
        def apply(frames, format, delay=sign * period):
            try:
                return reload(delay)[: len(frames)]
            except ValueError:  # no rgb image pairs at that offset
                return frames[:1]
        out.append(Fix(f"depth a frame {side}",
                       f"depth.txt's stamps run about one frame ({period * 1000:.0f} ms) {side} "
                       f"against rgb.txt's, so each rgb image is paired with the depth of its "
                       f"{'previous' if sign > 0 else 'next'} frame: "
                       f"{'subtract' if sign > 0 else 'add'} {period:.3f} s "
                       f"{'from' if sign > 0 else 'to'} depth.txt's stamps", apply))
    return tuple(out)


def folder_checks(scene: Scene) -> list[Check]:
    """Every check above on a loaded scene."""
    return [check_duplicates(scene), check_frozen_depth(scene.train),
            check_pairing(scene.record), check_camera_size(scene.record)]
