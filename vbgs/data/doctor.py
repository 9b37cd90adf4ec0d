"""A dataset doctor: is a loaded scene's geometry what the loaders promise?

Loaders hand out frames with camera-to-world poses in OpenCV axes, intrinsics in
pixels and depth in scene units (:mod:`vbgs.data.scene`). A file written under
another convention loads without complaint and learns a plausible-looking bad map,
so the checks here look at what a convention mix-up does to the numbers:

* **rotations**: orthonormal with determinant +1 (scaled, sheared, reflected poses);
* **intrinsics**: a field of view under 180 degrees, the principal point inside the image;
* **depth codes**: depth read from 16-bit PNGs whose codes are small integers (under
  :data:`SMALL_CODES`) was written in metres, not in the file's units;
* **depth values**: depth maps holding one value (constant) carry no shape to compare;
* **depth scale**: the camera's step between neighbouring frames against the median
  depth (a camera that moves many depths between frames has translations in other
  units than its depth);
* **consistency**: each frame's depth points projected into other frames agree with
  their depth (:func:`agreement`), against what the depth's own noise allows
  (:func:`expected_agreement`: neighbouring pixels of one frame agreeing); views are
  healthy only at NEAR_NOISE of that. A pose-convention mix-up (world-to-camera given
  for camera-to-world, OpenGL axes for OpenCV, a quaternion read in the wrong order),
  another camera's focal length or depth off by one of the common scale factors (1000,
  5000, 6553.5 codes per metre, metres) leaves few pixels agreeing. Every candidate fix
  (:data:`FIXES`, and the caller's: a TUM folder's depth paired a frame later or
  earlier, :func:`pairing_fixes`) is tried; one is named only when it brings
  the views to the agreement their noise allows, with the agreement before and after.
  Otherwise the check says what it saw and that no single fix explains it.

:func:`examine` runs them all (after a folder's own checks, given: :func:`folder_checks`,
duplicates, frozen depth, TUM pairing, intrinsics for another aspect) and returns a
:class:`Report`; :func:`refuse_bad_cameras` is the cheap subset that ``fit-scene`` runs
before any work.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from vbgs.data.scene import Frame, Scene, check_rotation
from vbgs.render.camera import Camera, opengl_to_opencv, project, unproject

# A projected point agrees with the other frame's depth within this share of it.
AGREE_TOLERANCE = 0.05
# Views that agree at under this share (median frame's best neighbour) fail even when no
# fix helps. Low on purpose: noisy sensors agree at 0.16-0.5 under AGREE_TOLERANCE (the
# synthetic room, object and walk with RealSense noise at 32-64 px), exact depth at
# 0.86-0.96.
POOR = 0.1
# Views are healthy when they agree at least this share of what their depth's own noise
# allows (:func:`expected_agreement`: neighbouring pixels of one frame agreeing within
# AGREE_TOLERANCE). Measured on the synthetic room at 32 px: exact depth 0.88 against 0.79,
# a Kinect's 0.93 against 0.83, a RealSense's 0.15 against 0.15; its depth read x5 0.39,
# /5 0.16, paired with the frame before 0.42, one depth map for every frame 0.41.
NEAR_NOISE = 0.8
# A frame pair overlaps when this share of one frame's points lands on the other's
# measured depth; a frame without such a neighbour is not scored.
MIN_OVERLAP = 0.1
# Points per frame used in the consistency check (a regular subsample of valid depth).
MAX_POINTS = 3000
# A camera stepping more than this many median depths between neighbouring frames has
# its translations in other units than its depth.
MAX_STEP_DEPTHS = 10.0
# Depth PNG codes below this, all integers, are metres written without the scale.
SMALL_CODES = 256
# A candidate fix is named, and the views fail, when it lifts agreement by at least this
# much: relative to the data's own agreement, so noisy depth does not fail by itself.
FIX_GAIN = 0.15


class Check(NamedTuple):
    """One check's verdict: ``ok`` None when it could not be measured."""

    name: str
    ok: bool | None
    message: str
    frames: tuple = ()  # the frames it concerns (indices into the frames examined)

    def as_dict(self) -> dict:
        return {"check": self.name, "ok": self.ok, "message": self.message,
                "frames": list(self.frames)}


class Fix(NamedTuple):
    """A candidate fix: a name, the change in words, and the frames it gives (from the
    frames as loaded and the format; see :func:`try_fixes`). A depth-units fix carries
    its ``factor`` (its words then depend on the depth scale read: :func:`fix_words`)."""

    name: str
    words: str
    apply: Callable[[list[Frame], str | None], list[Frame]]
    factor: float | None = None


class Report(NamedTuple):
    """Every check, the measured agreement, what the depth's own noise allows
    (``expected``) and, when one brings the views there, the fix that does."""

    checks: list[Check]
    agreement: float | None
    fix: str | None = None
    fix_words: str | None = None
    fix_agreement: float | None = None
    expected: float | None = None

    @property
    def healthy(self) -> bool:
        return all(c.ok is not False for c in self.checks)

    def as_dict(self) -> dict:
        return {"healthy": self.healthy, "agreement": self.agreement, "fix": self.fix,
                "fix_words": self.fix_words, "fix_agreement": self.fix_agreement,
                "expected_agreement": self.expected,
                "checks": [c.as_dict() for c in self.checks]}


# --------------------------------------------------------------------------- cameras


def rotation_problem(pose: np.ndarray) -> str | None:
    """What is wrong with a pose's rotation (scaled, sheared, reflected), or None."""
    try:
        check_rotation(np.asarray(pose)[:3, :3], "rotation")
    except ValueError as err:
        return str(err).removeprefix("rotation: ")
    return None


def intrinsics_problem(cam: Camera) -> str | None:
    """What is implausible about a camera's intrinsics, or None: focal lengths must be
    positive (a field of view under 180 degrees), the principal point inside the image."""
    if not (np.isfinite(cam.fx) and np.isfinite(cam.fy) and cam.fx > 0 and cam.fy > 0):
        return f"focal lengths fx={cam.fx}, fy={cam.fy} are not positive"
    if not (0 <= cam.cx <= cam.width and 0 <= cam.cy <= cam.height):
        return (f"principal point ({cam.cx:.1f}, {cam.cy:.1f}) lies outside the "
                f"{cam.width}x{cam.height} image; are these another camera's intrinsics?")
    return None


def field_of_view(cam: Camera) -> float:
    """Horizontal field of view in degrees."""
    return float(np.degrees(2 * np.arctan(0.5 * cam.width / cam.fx)))


def check_rotations(frames: list[Frame]) -> Check:
    bad = [(i, p) for i, f in enumerate(frames) if (p := rotation_problem(f.camera.pose))]
    if not bad:
        return Check("rotations", True, f"{len(frames)} rotations orthonormal, det +1")
    return Check("rotations", False, f"frame {bad[0][0]}: {bad[0][1]} ({len(bad)} frame(s))",
                 tuple(i for i, _ in bad))


def check_intrinsics(frames: list[Frame]) -> Check:
    bad = [(i, p) for i, f in enumerate(frames) if (p := intrinsics_problem(f.camera))]
    if bad:
        return Check("intrinsics", False, f"frame {bad[0][0]}: {bad[0][1]} "
                     f"({len(bad)} frame(s))", tuple(i for i, _ in bad))
    cam = frames[0].camera
    return Check("intrinsics", True, f"field of view {field_of_view(cam):.1f} degrees, "
                 f"principal point ({cam.cx:.1f}, {cam.cy:.1f}) in {cam.width}x{cam.height}")


# --------------------------------------------------------------------------- depth


def check_depth_codes(frames: list[Frame], depth_scale: float | None) -> Check:
    """Depth PNG codes (depth * scale) that are all small integers were written in
    metres (or another coarse unit) instead of depth * scale."""
    if not depth_scale:
        return Check("depth codes", None, "depth not read from PNG codes")
    codes = np.concatenate([f.depth[f.depth > 0] for f in frames]) * float(depth_scale)
    if not len(codes):
        return Check("depth codes", None, "no depth")
    integer = np.abs(codes - np.round(codes)).max() < 1e-2
    if integer and codes.max() < SMALL_CODES:
        values = np.unique(np.round(codes)).astype(int)
        return Check("depth codes", False,
                     f"the depth PNGs hold only {len(values)} distinct codes, all under "
                     f"{SMALL_CODES} ({values[:6].tolist()}...): depth in metres written as "
                     f"whole numbers to a 16-bit PNG? Write depth x {depth_scale:g} (the "
                     f"file's scale); --depth-scale 1 reads these as metres, but everything "
                     f"under a metre is lost")
    return Check("depth codes", True, f"depth codes up to {codes.max():.0f} at scale "
                 f"{depth_scale:g}")


# A frame's depth whose 5-95 percentile spread is under this share of its median holds one
# value: no shape to compare across views.
FLAT_SPREAD = 1e-3


def check_depth_values(frames: list[Frame]) -> Check:
    """Depth maps holding one value (a constant written for every pixel) carry no shape:
    any pose set can make such views agree, so no fix is named from them."""
    flat = []
    for i, f in enumerate(frames):
        d = f.depth[f.depth > 0]
        if len(d):
            lo, mid, hi = np.percentile(d, [5, 50, 95])
            if hi - lo <= FLAT_SPREAD * mid:
                flat.append(i)
    if len(flat) * 2 > len(frames):
        value = float(np.median(frames[flat[0]].depth[frames[flat[0]].depth > 0]))
        return Check("depth values", False, f"the depth of {len(flat)} of {len(frames)} frames "
                     f"holds one value ({value:.4g} in frame {flat[0]}): a constant depth map "
                     f"carries no shape; check the depth files or the model that wrote them",
                     tuple(flat))
    return Check("depth values", True, f"{len(frames) - len(flat)} of {len(frames)} depth "
                 f"maps hold a range of depths")


def camera_step(frames: list[Frame]) -> float:
    """Median distance between neighbouring frames' camera centres."""
    centres = np.stack([f.camera.position for f in frames])
    return float(np.median(np.linalg.norm(np.diff(centres, axis=0), axis=1)))


def check_depth_scale(frames: list[Frame]) -> Check:
    """The camera's step between neighbouring frames against the median depth."""
    depth = np.concatenate([f.depth[f.depth > 0] for f in frames])
    if len(frames) < 2 or not len(depth):
        return Check("depth scale", None, "needs two frames with depth")
    median, step = float(np.median(depth)), camera_step(frames)
    words = f"median depth {median:.4g}, median camera step {step:.4g}"
    if step > MAX_STEP_DEPTHS * median:
        return Check("depth scale", False,
                     f"{words}: the camera moves {step / median:.0f} median depths between "
                     f"neighbouring frames; translations and depth are in different units "
                     f"(millimetres and metres?)")
    return Check("depth scale", True, words)


# --------------------------------------------------------------------------- consistency


def _points(frame: Frame) -> np.ndarray:
    """At most MAX_POINTS of a frame's depth points, world ``[n, 3]``, a regular subsample."""
    xyz, _ = unproject(frame.camera, frame.rgb, frame.depth)
    return xyz[:: max(1, len(xyz) // MAX_POINTS)]


def pair_agreement(xyz: np.ndarray, other: Frame) -> tuple[float, float]:
    """Of world points ``xyz [n, 3]`` (one frame's depth), the share landing on ``other``'s
    measured depth, and of those the share whose depth agrees with it (within
    AGREE_TOLERANCE of it)."""
    if not len(xyz):
        return 0.0, 0.0
    cam = other.camera
    uv, z = project(cam, xyz)
    col, row = np.floor(uv[:, 0]).astype(np.int64), np.floor(uv[:, 1]).astype(np.int64)
    inside = (z > 0) & (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)
    seen = np.zeros(len(xyz), np.float64)
    seen[inside] = other.depth[row[inside], col[inside]]
    hit = seen > 0
    if not hit.any():
        return 0.0, 0.0
    agree = np.abs(z[hit] - seen[hit]) <= AGREE_TOLERANCE * seen[hit]
    return float(hit.mean()), float(agree.mean())


def neighbours(n: int, i: int, sample: list[int]) -> list[int]:
    """Frames compared with frame ``i``: its trajectory neighbours and the sample."""
    return sorted({j for j in (i - 2, i - 1, i + 1, i + 2, *sample) if 0 <= j < n and j != i})


def sample_frames(n: int, count: int) -> list[int]:
    """``count`` frame indices spread evenly over ``n``."""
    return sorted({int(round(x)) for x in np.linspace(0, n - 1, min(n, count))})


def agreement(frames: list[Frame], count: int = 8) -> tuple[float | None, list[float | None]]:
    """Multi-view consistency: for ``count`` frames spread over the sequence, the best
    agreement with any overlapping other frame (:func:`pair_agreement`); and their
    median (None when no frame overlaps another)."""
    sample = sample_frames(len(frames), count)
    per_frame = []
    for i in sample:
        xyz = _points(frames[i])
        best = None
        for j in neighbours(len(frames), i, sample):
            hit, agree = pair_agreement(xyz, frames[j])
            if hit >= MIN_OVERLAP:
                best = max(best or 0.0, agree)
        per_frame.append(best)
    scored = [a if a is not None else 0.0 for a in per_frame]
    if all(a is None for a in per_frame):
        return None, per_frame
    return float(np.median(scored)), per_frame


def local_agreement(frame: Frame) -> float | None:
    """Share of a frame's neighbouring pixel pairs (right and down) with depth whose depths
    agree within AGREE_TOLERANCE: what the depth's own noise (and its edges) allows two
    views of one surface to reach (None without such pairs)."""
    d = np.asarray(frame.depth, np.float64)
    agree = []
    for a, b in ((d[:, 1:], d[:, :-1]), (d[1:], d[:-1])):
        ok = (a > 0) & (b > 0)
        agree.append(np.abs(a - b)[ok] <= AGREE_TOLERANCE * b[ok])
    agree = np.concatenate(agree)
    return float(agree.mean()) if len(agree) else None


def expected_agreement(frames: list[Frame], count: int = 8) -> float | None:
    """The median over ``count`` frames of :func:`local_agreement` (None: no depth)."""
    values = [a for i in sample_frames(len(frames), count)
              if (a := local_agreement(frames[i])) is not None]
    return float(np.median(values)) if values else None


def _with_poses(frames: list[Frame], poses: list[np.ndarray]) -> list[Frame]:
    return [f._replace(camera=f.camera._replace(pose=np.asarray(p, np.float64)))
            for f, p in zip(frames, poses, strict=True)]


def _pose_fix(name: str, words: str, fix: Callable[[np.ndarray], np.ndarray]) -> Fix:
    """A fix of each pose as the file holds it: a Blender file's are OpenGL-axis poses,
    the loaded ones times diag(1, -1, -1, 1) (its own inverse, so the same map goes back)."""

    def apply(frames, format):
        file_axes = opengl_to_opencv if format == "blender" else (lambda p: p)
        return _with_poses(frames, [file_axes(fix(file_axes(np.asarray(f.camera.pose,
                                                                       np.float64))))
                                    for f in frames])

    return Fix(name, words, apply)


def _focal_fix(factor: float) -> Fix:
    def apply(frames, format):
        return [f._replace(camera=f.camera._replace(fx=f.camera.fx * factor,
                                                    fy=f.camera.fy * factor)) for f in frames]

    side = "short" if factor > 1 else "long"
    return Fix(f"focal x{factor:g}", f"the focal lengths are about {factor:g} x too {side}: "
               f"the intrinsics are another camera's? give this camera's with --intrinsics "
               f"fx,fy,cx,cy (Replica: a cam_params.json beside the folder)", apply)


# Depth PNG codes per metre of the formats and of users' files: millimetres (Blender,
# most sensors' raw output), TUM's 5000, Replica's 6553.5, and metres (1).
COMMON_SCALES = (1000.0, 5000.0, 6553.5, 1.0)


def _depth_fix(factor: float) -> Fix:
    def apply(frames, format):
        return [f._replace(depth=(f.depth * factor).astype(np.float32)) for f in frames]

    return Fix(f"depth x{factor:.4g}", "", apply, factor)


def fix_words(fix: Fix, depth_scale: float | None) -> str:
    """A fix's change in words; a depth-units fix's from the depth scale it was read at:
    the scale to give when the file's codes then read as one of :data:`COMMON_SCALES`,
    else the translations (the same geometry: every length of the depth against the
    poses)."""
    if fix.factor is None:
        return fix.words
    f = fix.factor
    if depth_scale:
        right = depth_scale / f
        if any(abs(right / c - 1) < 1e-3 for c in COMMON_SCALES if c != 1.0):
            return (f"the depth PNGs hold {right:g} codes per scene unit, not {depth_scale:g}: "
                    f"give --depth-scale {right:g} (read at {depth_scale:g} the depth is "
                    f"{max(f, 1 / f):.4g} x too {'short' if f > 1 else 'long'})")
    if f > 1:
        return (f"the poses' translations are in units {f:g} x longer than the depth's "
                f"(depth in metres, translations in millimetres?): divide each pose's "
                f"translation by {f:g}")
    return (f"the depth is in units {1 / f:g} x shorter than the poses' translations (depth "
            f"in millimetres, poses in metres?): divide the depth by {1 / f:g}")


def _quaternion_swapped(p):
    """The pose whose quaternion was written qw qx qy qz and read as qx qy qz qw."""
    from vbgs.data.formats import quaternion_to_matrix
    from vbgs.render.splats import quaternions_from_rotations

    w, x, y, z = quaternions_from_rotations(p[None, :3, :3])[0]  # what was read, (x,y,z,w)
    out = p.copy()
    out[:3, :3] = quaternion_to_matrix(y, z, w, x)  # the file's first value is qw
    return out


_AXES = ("the file's poses use the other camera axis convention than the format's "
         "(Blender/NeRF: OpenGL, x right, y up, z back; Replica, TUM: OpenCV, x right, y down, "
         "z forward)")

FIXES = (
    _pose_fix("w2c", "the file's poses are world-to-camera: invert each 4x4 (camera-to-world "
                     "is expected)", np.linalg.inv),
    _pose_fix("axes", f"{_AXES}: multiply each pose on the right by diag(1, -1, -1, 1)",
              opengl_to_opencv),
    _pose_fix("w2c+axes", "the file's poses are world-to-camera in the other axis convention: "
                          "invert each 4x4, then multiply it on the right by diag(1, -1, -1, 1)",
              lambda p: opengl_to_opencv(np.linalg.inv(p))),
    _pose_fix("quaternion-wxyz", "groundtruth.txt's quaternions are written qw qx qy qz; TUM "
                                 "writes tx ty tz qx qy qz qw: move qw to the end of each line",
              _quaternion_swapped),
    *(_focal_fix(k) for k in (0.5, 2 / 3, 1.5, 2.0)),
    *(_depth_fix(a / b) for a in COMMON_SCALES for b in COMMON_SCALES if a != b),
)
TUM_ONLY = ("quaternion-wxyz",)


def try_fixes(frames: list[Frame], format: str | None, count: int = 8,
              extra: tuple[Fix, ...] = ()):
    """Each candidate fix's agreement (:data:`FIXES` and ``extra``), best first:
    ``[(agreement, fix)]``."""
    out = []
    for fix in (*FIXES, *extra):
        if fix.name in TUM_ONLY and format != "tum":
            continue
        score, _ = agreement(fix.apply(frames, format), count)
        out.append((score or 0.0, fix))
    return sorted(out, key=lambda s: -s[0])


def check_consistency(frames: list[Frame], format: str | None = None, count: int = 8,
                      extra: tuple[Fix, ...] = (), depth_scale: float | None = None,
                      name_fix: bool = True
                      ) -> tuple[Check, float | None, tuple[float, Fix] | None]:
    """The views' agreement (:func:`agreement`) against what the depth's own noise allows
    (:func:`expected_agreement`) and against every candidate fix's (:data:`FIXES` and
    ``extra``). A fix is named only when it brings the views to NEAR_NOISE of what the
    noise allows and lifts them by FIX_GAIN. Failed when a fix does (that fix returned),
    when the views agree under NEAR_NOISE of what the noise allows or under POOR, or when
    no frame's depth lands on another's. Returns the check, the agreement and the fix."""
    if len(frames) < 2:
        return Check("consistency", None, "one frame: nothing to compare"), None, None
    score, per_frame = agreement(frames, count)
    expected = expected_agreement(frames, count)
    floor = max(POOR, NEAR_NOISE * (expected or 0.0))
    ranked = try_fixes(frames, format, count, extra)
    best = ranked[0]
    if not name_fix or best[0] < max(floor, (score or 0.0) + FIX_GAIN):
        best = None
    tried = f"{len(ranked)} fixes tried (the best, {_fix_label(ranked[0][1], depth_scale)}: " \
            f"{ranked[0][0]:.0%})"
    if score is None:
        words = "no frame's depth lands on another frame's depth: the poses put the views " \
                "apart (or the depth is far off)"
        if best is not None:
            return Check("consistency", False, f"{words}; {best[0]:.0%} once changed as "
                         f"below"), None, best
        return Check("consistency", False, f"{words}; no single fix explains it ({tried})"), \
            None, None
    sample = sample_frames(len(frames), count)
    poor = tuple(i for i, a in zip(sample, per_frame, strict=True) if (a or 0.0) < floor)
    words = (f"{score:.0%} of the pixels projected into a neighbouring frame agree with its "
             f"depth within {AGREE_TOLERANCE:.0%} (median over {len(sample)} frames; its "
             f"depth's own noise allows about {expected or 0.0:.0%})")
    if best is not None:
        return Check("consistency", False, f"only {words}; {best[0]:.0%} once changed as "
                     f"below (tried)", poor), score, best
    if score < floor:
        return Check("consistency", False, f"only {words}: the poses, intrinsics, depth or "
                     f"their pairing do not describe one scene, and no single fix explains "
                     f"it ({tried})", poor), score, None
    return Check("consistency", True, words, poor), score, None


def _fix_label(fix: Fix, depth_scale: float | None) -> str:
    if fix.factor is None:
        return fix.name
    return (f"--depth-scale {depth_scale / fix.factor:.6g}" if depth_scale
            else f"depth x {fix.factor:.4g}")


# --------------------------------------------------------------------------- a folder's own
# What a list file or a calibration file can get wrong while every frame still loads:
# duplicates (bit-identical images or poses; held-out views identical to a training frame,
# a leak), frozen depth (one depth map for frames whose cameras differ), the TUM pairing
# (rgb images left out for want of a depth image or a pose within 0.02 s) and intrinsics
# written for another aspect ratio. :func:`folder_checks` runs them on a loaded scene
# (the loaders' record carries the pairing and the sizes); :func:`leaked_views` is what
# fit-scene leaves out of its scores.

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


# --------------------------------------------------------------------------- entry points


def cheap_checks(frames: list[Frame], depth_scale: float | None = None) -> list[Check]:
    """The checks that cost next to nothing (no projection)."""
    return [check_rotations(frames), check_intrinsics(frames),
            check_depth_codes(frames, depth_scale), check_depth_values(frames),
            check_depth_scale(frames)]


def examine(frames: list[Frame], format: str | None = None, depth_scale: float | None = None,
            count: int = 8, extra: tuple[Fix, ...] = (), before: tuple[Check, ...] = ()
            ) -> Report:
    """Every check on ``frames`` (a trajectory in order), after the checks ``before``
    (a folder's own: :func:`folder_checks`), and, when a candidate fix (``extra``
    besides :data:`FIXES`) brings the views to the agreement their noise allows, that fix
    with the agreement before and after."""
    if not frames:
        raise ValueError("no frames to examine")
    cheap = cheap_checks(frames, depth_scale)
    shapeless = any(c.name == "depth values" and c.ok is False for c in cheap)
    consistency, score, best = check_consistency(frames, format, count, extra, depth_scale,
                                                  name_fix=not shapeless)
    checks = [*before, *cheap, consistency]
    expected = expected_agreement(frames, count)
    if best is None:
        return Report(checks, score, expected=expected)
    words = f"{fix_words(best[1], depth_scale)} (tried: agreement {score or 0.0:.0%} -> " \
            f"{best[0]:.0%})"
    return Report(checks, score, best[1].name, words, best[0], expected)


def refuse_bad_cameras(frames: list[Frame], depth_scale: float | None = None,
                       what: str = "scene") -> None:
    """The cheap checks, a failure refused in one line (ValueError) naming the frame."""
    for check in cheap_checks(frames, depth_scale):
        if check.ok is False:
            raise ValueError(f"{what}: {check.name}: {check.message}; "
                             f"`python -m experiments.run check --scene ...` says more")
