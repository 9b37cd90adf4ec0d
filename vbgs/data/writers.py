"""Write a scene's training trajectory in the Replica and TUM RGB-D layouts that
:mod:`vbgs.data.formats` reads (the Blender writer is :func:`vbgs.data.blender.write_blender`).

Both write one camera for every frame (frames of several intrinsics or sizes are
refused): Replica with a ``cam_params.json`` in the folder (the SLAM benchmarks'
layout, pixel centres at integers), TUM with none (the reader takes ``--intrinsics``
or a Freiburg preset). Depth is stored as 16-bit PNG codes at the format's scale.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from skimage import io as skio

from vbgs.data.calibration import CAM_PARAMS, REPLICA_DEPTH_SCALE, TUM_DEPTH_SCALE
from vbgs.data.depth_png import write_depth_png
from vbgs.data.scene import Frame
from vbgs.io_atomic import write_atomic, write_text_atomic
from vbgs.render.pixels import pixel_centre
from vbgs.render.splats import quaternions_from_rotations


def _one_camera(frames: list[Frame]) -> tuple[float, float, float, float, int, int]:
    """``fx, fy, cx, cy, w, h`` shared by every frame, pixel centres at integers."""
    cams = {(f.camera.fx, f.camera.fy, f.camera.cx, f.camera.cy, f.camera.width,
             f.camera.height) for f in frames}
    if len(cams) != 1:
        raise ValueError(f"the frames have {len(cams)} different cameras; these layouts "
                         f"store one (resize the frames first)")
    fx, fy, cx, cy, w, h = cams.pop()
    return float(fx), float(fy), cx - pixel_centre(0), cy - pixel_centre(0), int(w), int(h)


def _rgb(path: Path, rgb: np.ndarray) -> None:
    rgb8 = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, lambda tmp: skio.imsave(tmp, rgb8, check_contrast=False))


def write_replica(frames: list[Frame], folder) -> Path:
    """``results/frame%06d.jpg``, ``results/depth%06d.png``, ``traj.txt`` and
    ``cam_params.json`` of ``frames`` (a trajectory); return the folder."""
    folder = Path(folder)
    fx, fy, cx, cy, w, h = _one_camera(frames)
    for i, f in enumerate(frames):
        _rgb(folder / "results" / f"frame{i:06d}.jpg", f.rgb)
        write_depth_png(folder / "results" / f"depth{i:06d}.png", f.depth, REPLICA_DEPTH_SCALE)
    lines = [" ".join(f"{v:.9g}" for v in np.asarray(f.camera.pose).ravel()) for f in frames]
    write_text_atomic(folder / "traj.txt", "\n".join(lines) + "\n")
    camera = {"w": w, "h": h, "fx": fx, "fy": fy, "cx": cx, "cy": cy,
              "scale": REPLICA_DEPTH_SCALE}
    write_text_atomic(folder / CAM_PARAMS, json.dumps({"camera": camera}, indent=2))
    return folder


def write_tum(frames: list[Frame], folder, fps: float = 30.0) -> Path:
    """``rgb/``, ``depth/``, ``rgb.txt``, ``depth.txt`` and ``groundtruth.txt`` (``timestamp
    tx ty tz qx qy qz qw``) of ``frames`` at ``fps``; return the folder."""
    folder = Path(folder)
    _one_camera(frames)
    rgb, depth, truth = ["# rgb"], ["# depth"], ["# timestamp tx ty tz qx qy qz qw"]
    quats = quaternions_from_rotations(np.stack([f.camera.pose[:3, :3] for f in frames]))
    for i, (f, (qw, qx, qy, qz)) in enumerate(zip(frames, quats, strict=True)):
        t = f"{1000.0 + i / fps:.6f}"
        _rgb(folder / "rgb" / f"{t}.png", f.rgb)
        write_depth_png(folder / "depth" / f"{t}.png", f.depth, TUM_DEPTH_SCALE)
        rgb.append(f"{t} rgb/{t}.png")
        depth.append(f"{t} depth/{t}.png")
        x, y, z = f.camera.pose[:3, 3]
        truth.append(f"{t} {x:.9g} {y:.9g} {z:.9g} {qx:.9g} {qy:.9g} {qz:.9g} {qw:.9g}")
    for name, lines in (("rgb.txt", rgb), ("depth.txt", depth), ("groundtruth.txt", truth)):
        write_text_atomic(folder / name, "\n".join(lines) + "\n")
    return folder
