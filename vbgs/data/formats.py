"""Dataset loaders returning :class:`~vbgs.data.scene.Scene`, and :func:`load_scene`.

Three on-disk layouts are read (depth in metres, poses camera-to-world in
OpenCV axes after loading):

* **Blender / NeRF-synthetic** (``transforms_train.json``): see
  :mod:`vbgs.data.blender`, whose ``load_blender`` and ``write_blender`` are
  re-exported here.
* **Replica as packaged by SplaTAM/NICE-SLAM**: ``results/frame000000.jpg``,
  ``results/depth000000.png`` (16-bit, depth * 6553.5), ``traj.txt`` with one
  row-major 4x4 camera-to-world (OpenCV axes) per line, one line per frame.
* **TUM RGB-D**: ``rgb.txt``, ``depth.txt`` (``timestamp path`` lines, ``#``
  comments), ``groundtruth.txt`` (``timestamp tx ty tz qx qy qz qw``), depth
  PNGs at depth * 5000. Each rgb image is paired with the nearest depth image and
  the nearest pose, both within ``max_time_diff`` seconds; others are dropped.
  Poses are those of the colour camera's optical frame (x right, y down, z
  forward, i.e. OpenCV axes), camera-to-world. Lens distortion is ignored.

Published intrinsics (:class:`Intrinsics`) count pixel centres at integer
coordinates (OpenCV); the library puts them at ``col + 0.5``, so 0.5 is added
to cx, cy. They are rescaled when the images are not the published size.

Replica and TUM hold out every ``test_every``-th frame (positions
``test_every // 2, + test_every, ...`` of the strided sequence, so the stream
starts on a training frame), then every ``val_every``-th remaining frame as a
validation view (``Scene.val``, see :func:`~vbgs.data.scene.hold_out_validation`):
those are neither streamed nor scored. ``stride`` keeps every stride-th frame and
``max_frames`` caps the count before splitting; ``size`` resizes images and
intrinsics together (see :func:`~vbgs.data.scene.resize_frame`). Bounds come
from the training depth.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from vbgs.data.blender import VAL_EVERY, load_blender, write_blender
from vbgs.data.calibration import (
    REPLICA_DEPTH_SCALE,
    REPLICA_INTRINSICS,
    TUM_DEPTH_SCALE,
    TUM_FR1_INTRINSICS,
    Intrinsics,
    replica_calibration,
    tum_calibration,
)
from vbgs.data.depth_png import read_depth_png
from vbgs.data.images import read_rgb
from vbgs.data.scene import (
    Frame,
    Scene,
    bounds_from_frames,
    hold_out,
    hold_out_validation,
    require_some_depth,
    resize_frame,
    select,
    validate_frame,
)
from vbgs.data.stereo import REAL_SCENES
from vbgs.data.synthetic import SCENES, make_scene

__all__ = [
    "REPLICA_DEPTH_SCALE",
    "REPLICA_INTRINSICS",
    "TUM_DEPTH_SCALE",
    "TUM_FR1_INTRINSICS",
    "Intrinsics",
    "detect_format",
    "load_blender",
    "load_replica",
    "load_scene",
    "load_tum",
    "quaternion_to_matrix",
    "write_blender",
]

_WHITE = (1.0, 1.0, 1.0)  # RGBA frames are composited onto white, as the Blender loader does by default


# --------------------------------------------------------------------------- Replica


def _numbered(folder: Path, prefix: str, suffix: str) -> dict[int, Path]:
    pattern = re.compile(rf"{prefix}(\d+){re.escape(suffix)}$")
    return {
        int(m.group(1)): p
        for p in folder.glob(f"{prefix}*{suffix}")
        if (m := pattern.match(p.name))
    }


def _read_traj(path: Path) -> list[np.ndarray]:
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: Replica needs one 4x4 camera-to-world per line")
    poses = []
    for k, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            values = [float(x) for x in line.split()]
        except ValueError:
            values = []
        if len(values) != 16:
            raise ValueError(
                f"{path} line {k}: expected 16 numbers (a row-major 4x4 pose), got {line[:60]!r}"
            )
        poses.append(np.asarray(values, np.float64).reshape(4, 4))
    return poses


def load_replica(
    folder,
    size=None,
    max_frames: int | None = None,
    stride: int = 1,
    test_every: int | None = 8,
    intrinsics: Intrinsics | None = None,
    depth_scale: float | None = None,
    val_every: int | None = VAL_EVERY,
) -> Scene:
    """Load Replica in the SplaTAM layout (see module docstring); intrinsics and depth
    scale as given, else from a cam_params.json (:mod:`vbgs.data.calibration`)."""
    folder = Path(folder)
    intrinsics, depth_scale, calibration = replica_calibration(folder, intrinsics, depth_scale)
    results = folder / "results"
    if not results.is_dir():
        raise FileNotFoundError(
            f"{results} not found: Replica needs results/frame*.jpg and depth*.png"
        )
    images, depths = _numbered(results, "frame", ".jpg"), _numbered(results, "depth", ".png")
    if not images:
        raise FileNotFoundError(f"no frame*.jpg images in {results}")
    poses = _read_traj(folder / "traj.txt")
    if len(poses) != len(images):
        raise ValueError(
            f"{folder / 'traj.txt'} has {len(poses)} poses for {len(images)} "
            f"frame*.jpg images in {results}; they must match one to one"
        )
    ids = sorted(images)
    frames = []
    for k in select(len(ids), stride, max_frames):
        i = ids[k]
        if i not in depths:
            raise FileNotFoundError(
                f"{images[i].name} has no depth image: expected "
                f"{results / f'depth{images[i].name[5:-4]}.png'}"
            )
        rgb = read_rgb(images[i], background=_WHITE)
        if not frames:
            calibration = {**calibration, **stored_size(intrinsics, rgb)}
        cam = intrinsics.camera(rgb.shape[1], rgb.shape[0], poses[k])
        depth = read_depth_png(depths[i], depth_scale)
        frame = validate_frame(Frame(rgb, depth, cam), f"{images[i]} (depth {depths[i].name})")
        frames.append(resize_frame(require_some_depth(frame, f"{depths[i]}"), size))
    return _split(folder.name, frames, test_every, val_every, calibration)


def stored_size(intrinsics: Intrinsics, rgb: np.ndarray) -> dict:
    """The image size the intrinsics were written for, when it is known, and the size of
    the images as stored (a record's ``intrinsics_for``, ``images_stored``)."""
    if not intrinsics.width:
        return {}
    return {"intrinsics_for": [int(intrinsics.width), int(intrinsics.height)],
            "images_stored": [int(rgb.shape[1]), int(rgb.shape[0])]}


def _split(name: str, frames: list[Frame], test_every, val_every, calibration) -> Scene:
    """A scene from one trajectory: test views held out first, then validation views
    from what is left (see the module docstring); bounds from the training frames."""
    train, test = hold_out(frames, test_every)
    train, val = hold_out_validation(train, val_every)
    return Scene(name, train, test, bounds_from_frames(train), val=val, record=calibration)


# --------------------------------------------------------------------------- TUM RGB-D


def _read_list(path: Path, n_values: int) -> tuple[np.ndarray, list[list[str]]]:
    """Timestamps ``[n]`` and the remaining fields of a TUM list file (``#`` comments)."""
    if not path.is_file():
        raise FileNotFoundError(
            f"{path} not found: a TUM RGB-D folder needs rgb.txt, depth.txt and groundtruth.txt"
        )
    stamps, rows = [], []
    for k, line in enumerate(path.read_text().splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        try:
            if len(fields) != n_values + 1:
                raise ValueError
            stamps.append(float(fields[0]))
        except ValueError:
            raise ValueError(
                f"{path} line {k}: expected a timestamp and {n_values} value(s), got {line[:60]!r}"
            ) from None
        rows.append(fields[1:])
    if not stamps:
        raise ValueError(f"{path} lists no entries")
    return np.asarray(stamps), rows


def _nearest(stamps: np.ndarray, query: float) -> tuple[int, float]:
    """Index into sorted ``stamps`` of the one closest to ``query``, and the time gap."""
    j = int(np.searchsorted(stamps, query))
    best = min(
        (c for c in (j - 1, j) if 0 <= c < len(stamps)), key=lambda c: abs(stamps[c] - query)
    )
    return best, abs(stamps[best] - query)


def quaternion_to_matrix(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    """Rotation ``[3, 3]`` of the (normalised) Hamilton quaternion ``(qx, qy, qz, qw)``."""
    q = np.array([qw, qx, qy, qz], np.float64)
    norm = np.linalg.norm(q)
    if not (np.isfinite(norm) and norm > 0):
        raise ValueError(f"quaternion (qx, qy, qz, qw) = {(qx, qy, qz, qw)} has no direction "
                         f"(zero or not finite); a rotation needs a unit quaternion")
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def load_tum(
    folder,
    size=None,
    max_frames: int | None = None,
    stride: int = 1,
    test_every: int | None = 8,
    intrinsics: Intrinsics | None = None,
    depth_scale: float | None = None,
    max_time_diff: float = 0.02,
    val_every: int | None = VAL_EVERY,
    depth_delay: float = 0.0,
) -> Scene:
    """Load a TUM RGB-D sequence (see module docstring); intrinsics and depth scale as
    given, else the Freiburg preset the folder's name names (:mod:`vbgs.data.calibration`).
    ``depth_delay`` (seconds) is taken off every depth.txt stamp before pairing (a depth
    clock running late). The record says how the rgb images were paired
    (:func:`pairing_record`)."""
    folder = Path(folder)
    intrinsics, depth_scale, calibration = tum_calibration(folder, intrinsics, depth_scale)
    rgb_t, rgb_rows = _read_list(folder / "rgb.txt", 1)
    depth_t, depth_rows = _read_list(folder / "depth.txt", 1)
    depth_t = depth_t - depth_delay
    pose_t, pose_rows = _read_list(folder / "groundtruth.txt", 7)
    d_order, p_order = np.argsort(depth_t), np.argsort(pose_t)
    matches, no_depth, no_pose = [], 0, 0
    for i in np.argsort(rgb_t, kind="stable"):
        jd, dd = _nearest(depth_t[d_order], rgb_t[i])
        jp, dp = _nearest(pose_t[p_order], rgb_t[i])
        no_depth, no_pose = no_depth + (dd > max_time_diff), no_pose + (dp > max_time_diff)
        if dd <= max_time_diff and dp <= max_time_diff:
            matches.append((i, d_order[jd], p_order[jp]))
    if not matches:
        raise ValueError(
            f"{folder}: no rgb image has both a depth image and a pose within "
            f"{max_time_diff} s; check the timestamps or raise max_time_diff"
        )
    calibration = {**calibration, "pairing": pairing_record(
        rgb_t, pose_t, [depth_rows[jd][0] for _, jd, _ in matches], no_depth, no_pose,
        max_time_diff, depth_delay)}
    frames = []
    for k in select(len(matches), stride, max_frames):
        i, jd, jp = matches[k]
        values = [float(v) for v in pose_rows[jp]]
        pose = np.eye(4)
        try:
            pose[:3, :3], pose[:3, 3] = quaternion_to_matrix(*values[3:]), values[:3]
        except ValueError as err:
            raise ValueError(f"{folder / 'groundtruth.txt'} at {pose_t[jp]}: {err}") from None
        rgb = read_rgb(folder / rgb_rows[i][0], background=_WHITE)
        if not frames:
            calibration = {**calibration, **stored_size(intrinsics, rgb)}
        depth = read_depth_png(folder / depth_rows[jd][0], depth_scale)
        cam = intrinsics.camera(rgb.shape[1], rgb.shape[0], pose)
        what = f"{folder / rgb_rows[i][0]} (depth {depth_rows[jd][0]})"
        frame = require_some_depth(validate_frame(Frame(rgb, depth, cam), what), what)
        frames.append(resize_frame(frame, size))
    return _split(folder.name, frames, test_every, val_every, calibration)


def pairing_record(rgb_t, pose_t, depth_files: list[str], no_depth: int, no_pose: int,
                   max_time_diff: float, depth_delay: float = 0.0) -> dict:
    """How a TUM folder's rgb images found their depth and pose (each the nearest within
    ``max_time_diff`` s, the benchmark's association rule): images listed, those left out
    for want of a depth image or a pose, the span groundtruth.txt covers, the frame period
    and the depth files paired with more than one image."""
    rgb_t = np.sort(np.asarray(rgb_t, np.float64))
    names, counts = np.unique(np.asarray(depth_files), return_counts=True)
    return {"rgb_listed": len(rgb_t), "rgb_paired": len(depth_files),
            "rgb_without_depth": int(no_depth), "rgb_without_pose": int(no_pose),
            "rgb_span": [float(rgb_t[0]), float(rgb_t[-1])],
            "pose_span": [float(np.min(pose_t)), float(np.max(pose_t))],
            "frame_period": float(np.median(np.diff(rgb_t))) if len(rgb_t) > 1 else None,
            "depth_files_reused": int((counts > 1).sum()),
            "depth_file_most_reused": [str(names[counts.argmax()]), int(counts.max())],
            "max_time_diff": max_time_diff, "depth_delay": depth_delay}


# --------------------------------------------------------------------------- entry point

LOADERS = {"blender": load_blender, "replica": load_replica, "tum": load_tum}
FORMAT_NAMES = {"blender": "Blender", "replica": "Replica", "tum": "TUM RGB-D"}


def detect_format(folder) -> str:
    """``"blender"``, ``"replica"`` or ``"tum"`` from the files in ``folder``."""
    folder = Path(folder)
    found = {name: marks for name, marks in (
        ("blender", sorted(p.name for p in folder.glob("transforms_*.json"))),
        ("replica", [n for n in ("traj.txt", "results") if (folder / n).is_file()
                     or any((folder / n).glob("frame*.jpg"))]),
        ("tum", [n for n in ("rgb.txt", "depth.txt", "groundtruth.txt")
                 if (folder / n).exists()])) if marks}
    if len(found) > 1:
        held = "; ".join(f"{', '.join(m)} ({FORMAT_NAMES[k]})" for k, m in found.items())
        raise ValueError(f"{folder} holds the files of {len(found)} dataset formats: {held}; "
                         f"give --format {' or --format '.join(found)} to say which to read")
    if found:
        return next(iter(found))
    raise FileNotFoundError(
        f"cannot tell the dataset format of {folder}: expected transforms_train.json (Blender), "
        f"traj.txt + results/ (Replica) or rgb.txt + depth.txt + groundtruth.txt (TUM RGB-D)"
    )


def load_scene(path_or_name, format: str | None = None, **kw) -> Scene:
    """A synthetic scene by name ("object", "room", "walk"), a real one-frame scene by name
    ("motorcycle", :mod:`vbgs.data.stereo`; only ``size`` applies) or a dataset folder
    (format detected or given).

    An existing folder wins over a synthetic name. The format is detected by
    :func:`detect_format` unless ``format`` ("blender", "replica", "tum") is given.

    ``kw`` go to :func:`~vbgs.data.synthetic.make_scene` or to the loader
    (``size``, ``max_frames``, ``stride``, ...).
    """
    path = Path(path_or_name)
    if str(path_or_name) in SCENES and not path.is_dir():
        return make_scene(str(path_or_name), **kw)
    if str(path_or_name) in REAL_SCENES and not path.is_dir():
        return REAL_SCENES[str(path_or_name)](size=kw.get("size"))
    if not path.is_dir():
        raise FileNotFoundError(
            f"{path_or_name!r} is neither a dataset folder nor a built-in scene "
            f"name ({', '.join([*SCENES, *REAL_SCENES])})"
        )
    format = format or detect_format(path)
    if format not in LOADERS:
        raise ValueError(f"unknown dataset format {format!r}; known: {', '.join(LOADERS)}")
    return LOADERS[format](path, **kw)
