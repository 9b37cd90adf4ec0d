"""RGB-D data types, and the small utilities every source of frames shares.

Conventions (see :mod:`vbgs.render.camera`):

* ``rgb`` is float32 ``[h, w, 3]`` in [0, 1];
* ``depth`` is float32 ``[h, w]`` z-depth (distance along the camera's optical
  axis, not along the ray) in scene units; 0 marks a pixel without depth;
* ``camera.pose`` is camera-to-world with OpenCV axes (x right, y down, z forward).

Loaders and generators produce frames that pass :func:`validate_frame`; callers
that build frames themselves can run it to get a message naming what is wrong.
The utilities (bounds, resizing, image reading, frame selection and hold-out)
are shared by :mod:`vbgs.data.blender` and :mod:`vbgs.data.formats`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from skimage.transform import resize

from vbgs.render.camera import Camera, unproject
from vbgs.render.pixels import pixel_centre


class Frame(NamedTuple):
    """One RGB-D image with its camera.

    rgb: ``[h, w, 3]`` float32 in [0, 1]; depth: ``[h, w]`` float32 z-depth in
    scene units, 0 = missing; camera: intrinsics, size and camera-to-world pose.
    """

    rgb: np.ndarray  # [h, w, 3]
    depth: np.ndarray  # [h, w]
    camera: Camera


class Scene(NamedTuple):
    """A set of RGB-D frames of one static scene.

    name: a short label (synthetic scene name or dataset folder name);
    train: frames in trajectory order (streaming order matters: consecutive frames
    are neighbouring views); test: held-out views for evaluation only (scores are
    reported on them, nothing is chosen on them);
    bounds: world-space ``(lo [3], hi [3])`` box around the content;
    background: the rgb colour seen where no geometry is hit (pixels with depth 0 in
    object-centric scenes), the colour a renderer should composite onto;
    val: validation views, apart from both the training and the test views: whatever
    is still tuned (render settings) is chosen on these, never on ``test``. Last, with
    a default, so positional construction ``Scene(name, train, test, bounds)`` keeps
    working (a scene built that way has none);
    first_state, changes: a scene that changes while it is streamed
    (:mod:`vbgs.data.changing`): its test views as the world was before the changes, and
    the training frames at which it changed (empty for a static scene);
    record: what a loader wants said in a run's record: where a dataset's intrinsics and
    depth scale came from
    (:func:`vbgs.data.calibration.provenance`), views left out; empty for synthetic scenes.
    """

    name: str
    train: list[Frame]
    test: list[Frame]
    bounds: tuple[np.ndarray, np.ndarray]
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    val: list[Frame] = []  # a NamedTuple field: shared default, never mutated
    record: dict = {}  # shared default, never mutated
    # a scene that changes while streamed (vbgs.data.changing): the test views' poses in
    # the first state, and the training frames at which the world changed
    first_state: list[Frame] = []  # shared default, never mutated
    changes: tuple[int, ...] = ()


def validate_frame(frame: Frame, what: str = "frame") -> Frame:
    """Check shapes, dtypes and values of a frame; return it unchanged or raise ValueError.

    ``what`` names the frame in the message (e.g. ``"train frame 3"``).
    """
    rgb, depth, cam = frame.rgb, frame.depth, frame.camera
    if not isinstance(cam, Camera):
        raise TypeError(f"{what}: camera must be a vbgs.render.camera.Camera, got {type(cam).__name__}")
    shape = (int(cam.height), int(cam.width))
    if not isinstance(rgb, np.ndarray) or rgb.shape != shape + (3,):
        raise ValueError(
            f"{what}: rgb has shape {getattr(rgb, 'shape', None)}, expected {shape + (3,)} "
            f"(height, width, 3) to match the camera; resize the image or fix the camera size"
        )
    if not isinstance(depth, np.ndarray) or depth.shape != shape:
        raise ValueError(
            f"{what}: depth has shape {getattr(depth, 'shape', None)}, expected {shape} "
            f"to match the camera; pass a single-channel [h, w] depth map"
        )
    for name, arr in (("rgb", rgb), ("depth", depth)):
        if arr.dtype != np.float32:
            raise ValueError(
                f"{what}: {name} has dtype {arr.dtype}, expected float32; convert with "
                f"arr.astype(np.float32) (and divide 8-bit colour by 255)"
            )
    n_bad = int(np.count_nonzero(~np.isfinite(rgb)))
    if n_bad:
        raise ValueError(f"{what}: rgb has {n_bad} NaN/inf values; fix or inpaint the image")
    if rgb.size and (rgb.min() < 0.0 or rgb.max() > 1.0):
        raise ValueError(
            f"{what}: rgb values span [{rgb.min():.3g}, {rgb.max():.3g}], expected [0, 1]; "
            f"divide 8-bit images by 255"
        )
    n_bad = int(np.count_nonzero(~np.isfinite(depth) | (depth < 0)))
    if n_bad:
        raise ValueError(
            f"{what}: depth has {n_bad} NaN, inf or negative values; mark missing depth "
            f"with 0, e.g. np.where(np.isfinite(d) & (d > 0), d, 0)"
        )
    pose = np.asarray(cam.pose)
    if pose.shape != (4, 4):
        raise ValueError(f"{what}: camera pose must be a [4, 4] matrix, got shape {pose.shape}")
    n_bad = int(np.count_nonzero(~np.isfinite(pose)))
    if n_bad:
        raise ValueError(
            f"{what}: camera pose has {n_bad} NaN/inf entries; fix the pose (camera-to-world "
            f"4x4) in the dataset"
        )
    check_rotation(pose[:3, :3], what)
    if not (np.isfinite(cam.fx) and np.isfinite(cam.fy) and cam.fx > 0 and cam.fy > 0):
        raise ValueError(f"{what}: focal lengths must be positive, got fx={cam.fx}, fy={cam.fy}")
    return frame


# A pose's rotation may differ from an orthonormal matrix by this much (entries of
# R^T R - I): float32 files and quaternion rounding stay well inside it.
ROTATION_TOLERANCE = 1e-3


def check_rotation(rotation: np.ndarray, what: str = "frame") -> None:
    """Refuse a camera-to-world rotation ``[3, 3]`` that is not a rotation: scaled,
    sheared, or a reflection (det -1), naming which (each gave a plausible-looking bad
    score before it was checked)."""
    r = np.asarray(rotation, np.float64)
    gram = r.T @ r
    if np.abs(gram - np.eye(3)).max() > ROTATION_TOLERANCE:
        scales = np.sqrt(np.clip(np.diag(gram), 0, None))
        off = np.abs(gram - np.diag(np.diag(gram))).max()
        kind = (f"its columns have lengths {np.round(scales, 4).tolist()} (scaled)"
                if off <= ROTATION_TOLERANCE * max(scales.max()**2, 1.0)
                else "its columns are not perpendicular (sheared)")
        raise ValueError(f"{what}: the pose's rotation is not orthonormal: {kind}; a "
                         f"camera-to-world pose holds a pure rotation and a translation")
    if np.linalg.det(r) < 0:
        raise ValueError(f"{what}: the pose's rotation has determinant -1 (a reflection): "
                         f"one axis is flipped; check the axis convention (OpenGL/NeRF "
                         f"y up, z back against OpenCV y down, z forward) of the file")


def require_some_depth(frame: Frame, what: str = "frame") -> Frame:
    """Refuse a frame whose depth is 0 (missing) at every pixel: it gives no 3-D point
    to learn from. Return it unchanged otherwise."""
    if not np.any(frame.depth > 0):
        raise ValueError(
            f"{what}: depth is 0 (missing) at every pixel, so the frame has no 3-D points; "
            f"check the depth file and its scale, or estimate depth with `python -m depth`"
        )
    return frame


def validate_scene(scene: Scene) -> Scene:
    """Validate every frame and the bounds of a scene; return it unchanged or raise ValueError."""
    if not scene.train:
        raise ValueError(f"scene {scene.name!r} has no training frames")
    for split, frames in (("train", scene.train), ("test", scene.test), ("val", scene.val)):
        for i, frame in enumerate(frames):
            validate_frame(frame, f"scene {scene.name!r} {split} frame {i}")
    lo, hi = (np.asarray(b) for b in scene.bounds)
    if lo.shape != (3,) or hi.shape != (3,) or not np.all(lo <= hi):
        raise ValueError(f"scene {scene.name!r}: bounds must be (lo[3], hi[3]) with lo <= hi")
    return scene


def scale_scene(scene: Scene, factor: float) -> Scene:
    """The same scene with every length times ``factor`` (depth, camera positions, bounds):
    a scene given in other units. Nothing a learner or renderer does should change but
    the units of its lengths."""
    if not (np.isfinite(factor) and factor > 0):
        raise ValueError(f"a scene's scale must be a finite number > 0, got {factor!r}")

    def frame(f: Frame) -> Frame:
        pose = np.array(f.camera.pose, np.float64)
        pose[:3, 3] *= factor
        return f._replace(depth=(f.depth * factor).astype(np.float32),
                          camera=f.camera._replace(pose=pose))

    lo, hi = scene.bounds
    return scene._replace(train=[frame(f) for f in scene.train],
                          test=[frame(f) for f in scene.test],
                          val=[frame(f) for f in scene.val],
                          bounds=(np.asarray(lo) * factor, np.asarray(hi) * factor))


def bounds_from_frames(frames: list[Frame], max_depth: float = np.inf):
    """World box ``(lo [3], hi [3])`` float32 around all valid depth points of ``frames``.

    Without any valid depth (an RGB-only dataset) it falls back to the box around
    the camera centres.
    """
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for f in frames:
        xyz, _ = unproject(f.camera, f.rgb, f.depth, max_depth)  # [n, 3]
        if len(xyz):
            lo, hi = np.minimum(lo, xyz.min(0)), np.maximum(hi, xyz.max(0))
    if not np.all(np.isfinite(lo)):
        if not frames:
            raise ValueError("no frames, so the scene bounds are unknown")
        centres = np.stack([f.camera.position for f in frames])  # [n, 3]
        lo, hi = centres.min(0), centres.max(0)
    return lo.astype(np.float32), hi.astype(np.float32)


def select(n: int, stride: int = 1, max_frames: int | None = None) -> list[int]:
    """Indices of every ``stride``-th of ``n`` frames, at most ``max_frames`` of them."""
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    return list(range(0, n, stride))[:max_frames]


def hold_out(frames: list, every: int | None) -> tuple[list, list]:
    """Split a sequence into ``(train, test)``: positions ``every // 2 + j * every`` are test.

    Starting at ``every // 2`` keeps the first frame of the stream in training.
    ``every`` None or 0 holds nothing out.
    """
    if not every:
        return list(frames), []
    test = [i % every == every // 2 for i in range(len(frames))]
    return [f for f, t in zip(frames, test, strict=True) if not t], [
        f for f, t in zip(frames, test, strict=True) if t
    ]


def hold_out_validation(frames: list, every: int | None) -> tuple[list, list]:
    """Split training frames into ``(train, val)`` when a dataset ships no validation
    split: positions ``every - 1 + j * every`` are validation views (every ``every``-th
    frame, the first frame kept for training; :func:`hold_out` puts its test frames
    at ``every // 2 + j * every``, so applied after it the two rarely pick neighbours).
    ``every`` None or 0 holds nothing out."""
    if not every:
        return list(frames), []
    val = [i % every == every - 1 for i in range(len(frames))]
    return [f for f, v in zip(frames, val, strict=True) if not v], [
        f for f, v in zip(frames, val, strict=True) if v
    ]


def parse_size(size) -> int | tuple[int, int]:
    """A frame size as given on a command line or in a TOML file: ``"640x480"`` (or
    ``"640X480"``, a ``[640, 480]`` pair) is ``(width, height)``; a single number
    (``128``, ``"128"``) stays a number (a square synthetic frame, a dataset's longer
    side: :func:`target_size`). Both sides must be positive integers."""
    what = f"size {size!r}"
    if isinstance(size, str):
        parts = size.strip().lower().split("x")
        if len(parts) not in (1, 2) or not all(p.strip().isdigit() for p in parts):
            raise ValueError(f"{what} is not a size: give one number (128: square) or "
                             f"WIDTHxHEIGHT (640x480)")
        size = int(parts[0]) if len(parts) == 1 else tuple(int(p) for p in parts)
    if isinstance(size, (list, tuple)):
        if len(size) != 2 or not all(isinstance(v, (int, np.integer)) and not isinstance(
                v, bool) for v in size):
            raise ValueError(f"{what} is not a size: a pair must be two integers "
                             f"(width, height), e.g. (640, 480)")
        if min(size) < 1:
            raise ValueError(f"{what}: width and height must be at least 1 pixel")
        return int(size[0]), int(size[1])
    if not isinstance(size, (int, np.integer)) or isinstance(size, bool):
        raise ValueError(f"{what} is not a size: give one number (128: square) or "
                         f"WIDTHxHEIGHT (640x480)")
    if size < 1:
        raise ValueError(f"{what}: the side must be at least 1 pixel")
    return int(size)


def size_pixels(size) -> int:
    """Pixels of a frame of ``size`` (:func:`parse_size`; a number is a square side)."""
    size = parse_size(size)
    return size * size if isinstance(size, int) else size[0] * size[1]


def size_text(size) -> str:
    """``size`` as :func:`parse_size` reads it back: ``"128"`` or ``"640x480"``."""
    size = parse_size(size)
    return str(size) if isinstance(size, int) else f"{size[0]}x{size[1]}"


def target_size(width: int, height: int, size) -> tuple[int, int]:
    """Output ``(width, height)`` for a requested ``size``.

    ``None`` keeps the size; an int is the new longer side (aspect ratio kept,
    rounded); a pair is ``(width, height)``.
    """
    if size is None:
        return int(width), int(height)
    if np.ndim(size) == 0:
        s = int(size) / max(width, height)
        return max(1, round(width * s)), max(1, round(height * s))
    new_w, new_h = (int(x) for x in size)
    return new_w, new_h


def resize_frame(frame: Frame, size) -> Frame:
    """Resize a frame to ``size`` (see :func:`target_size`), intrinsics consistently.

    With pixel centres at ``col + 0.5`` a pixel edge at ``u`` maps to ``u * sx``,
    so ``fx, cx`` scale by ``sx = new_w / w`` and ``fy, cy`` by ``sy`` exactly.
    Colour is area-averaged when shrinking (anti-aliased); depth takes the source
    pixel nearest each new pixel centre, so no depth is invented between surfaces
    or from missing (0) pixels.
    """
    cam = frame.camera
    new_w, new_h = target_size(cam.width, cam.height, size)
    if (new_w, new_h) == (cam.width, cam.height):
        return frame
    sx, sy = new_w / cam.width, new_h / cam.height
    rgb = resize(frame.rgb, (new_h, new_w), order=1, anti_aliasing=sx < 1 or sy < 1)
    rows = np.minimum((pixel_centre(np.arange(new_h)) / sy).astype(int), cam.height - 1)  # [new_h]
    cols = np.minimum((pixel_centre(np.arange(new_w)) / sx).astype(int), cam.width - 1)  # [new_w]
    depth = frame.depth[rows[:, None], cols[None, :]]
    camera = cam._replace(
        fx=cam.fx * sx, fy=cam.fy * sy, cx=cam.cx * sx, cy=cam.cy * sy, width=new_w, height=new_h
    )
    return Frame(np.clip(rgb, 0.0, 1.0).astype(np.float32), depth.astype(np.float32), camera)


# A view lies inside the trained span when its camera is within this many typical
# spacings of the trained frames (median distance to a trained frame's nearest) of one.
SPAN_SPACINGS = 1.5


def inside_span(trained: list[Frame], views: list[Frame]) -> np.ndarray:
    """Mask ``[len(views)]``: which views' camera centres lie near the trained frames
    (the nearest trained camera within SPAN_SPACINGS of their typical spacing), so a
    view scored after training on part of a trajectory shows ground that was seen."""
    if not views:
        return np.zeros(0, bool)
    centres = np.stack([f.camera.position for f in trained])  # [n, 3]
    if len(centres) < 2:
        return np.ones(len(views), bool)  # no spacing to measure: a 1-frame scene is warned about
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    spacing = float(np.median(gaps.min(axis=1)))
    at = np.stack([f.camera.position for f in views])  # [m, 3]
    nearest = np.linalg.norm(at[:, None] - centres[None], axis=-1).min(axis=1)
    return nearest <= SPAN_SPACINGS * spacing
