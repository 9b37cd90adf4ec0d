"""Intrinsics and depth scales of the dataset formats: where each comes from.

Every loader takes ``intrinsics`` (``fx, fy, cx, cy`` in pixels of the images as
stored, pixel centres at integers as published and as OpenCV counts them) and
``depth_scale`` (depth PNG codes per scene unit) from the caller when given
(``--intrinsics``, ``--depth-scale``); otherwise from the folder when it carries
them; otherwise from the format's published defaults:

* Replica: a ``cam_params.json`` in the folder or beside it (the SLAM benchmarks'
  layout, ``{"camera": {"w", "h", "fx", "fy", "cx", "cy", "scale"}}``), else the
  Replica renders' 1200x680, f 600, depth * 6553.5;
* TUM RGB-D: the preset of the sensor the folder's name names (``freiburg1``,
  ``freiburg2``, ``freiburg3`` or ``fr1``..``fr3``), else fr1's; depth * 5000;
* Blender: the transforms files (see :mod:`vbgs.data.blender`); depth PNGs in
  millimetres.

:func:`provenance` is what a run's record says about them.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from vbgs.render.camera import Camera
from vbgs.render.pixels import pixel_centre

REPLICA_DEPTH_SCALE = 6553.5
TUM_DEPTH_SCALE = 5000.0
CAM_PARAMS = "cam_params.json"


class Intrinsics(NamedTuple):
    """Pinhole intrinsics, pixel centres at integers, for ``width x height`` images
    (None: for the images as they are, whatever their size)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int | None = None
    height: int | None = None

    def camera(self, width: int, height: int, pose: np.ndarray) -> Camera:
        """A library :class:`Camera` for images of ``width x height`` (rescaled if they differ)."""
        sx = width / self.width if self.width else 1.0
        sy = height / self.height if self.height else 1.0
        return Camera(
            self.fx * sx,
            self.fy * sy,
            pixel_centre(self.cx) * sx,
            pixel_centre(self.cy) * sy,
            int(width),
            int(height),
            np.asarray(pose, np.float64),
        )


REPLICA_INTRINSICS = Intrinsics(600.0, 600.0, 599.5, 339.5, 1200, 680)
# The published TUM RGB-D colour-camera intrinsics of the three Freiburg sensors.
TUM_PRESETS = {
    "fr1": Intrinsics(517.3, 516.5, 318.6, 255.3, 640, 480),
    "fr2": Intrinsics(520.9, 521.0, 325.1, 249.7, 640, 480),
    "fr3": Intrinsics(535.4, 539.2, 320.1, 247.6, 640, 480),
}
TUM_FR1_INTRINSICS = TUM_PRESETS["fr1"]


def _number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ValueError(f"{what} is {value!r}; give a finite number")
    return float(value)


def check_intrinsics(values, what: str = "--intrinsics") -> Intrinsics:
    """``fx, fy, cx, cy`` (text ``"fx,fy,cx,cy"`` or four numbers) as :class:`Intrinsics`
    for images of any size; focal lengths must be positive, the principal point >= 0."""
    if isinstance(values, Intrinsics):
        return values
    if isinstance(values, str):
        try:
            values = [float(v) for v in values.split(",")]
        except ValueError:
            raise ValueError(f"{what} {values!r}: give four numbers fx,fy,cx,cy "
                             f"(pixels)") from None
    values = list(values)
    if len(values) != 4:
        raise ValueError(f"{what}: give four numbers fx,fy,cx,cy (pixels), got {len(values)}")
    fx, fy, cx, cy = (_number(v, f"{what} {k}") for v, k in zip(values, "fx fy cx cy".split(),
                                                                strict=True))
    if fx <= 0 or fy <= 0:
        raise ValueError(f"{what}: focal lengths must be > 0 pixels, got fx={fx:g}, fy={fy:g}")
    if cx < 0 or cy < 0:
        raise ValueError(f"{what}: the principal point lies in the image (>= 0), got "
                         f"cx={cx:g}, cy={cy:g}")
    return Intrinsics(fx, fy, cx, cy)


def check_depth_scale(scale, what: str = "--depth-scale") -> float:
    """A depth scale (PNG codes per scene unit) must be a finite number > 0."""
    scale = _number(scale, what)
    if scale <= 0:
        raise ValueError(f"{what} must be > 0 (depth PNG codes per scene unit: 1000 for "
                         f"millimetres, 5000 for TUM, 6553.5 for Replica), got {scale:g}")
    return scale


def cam_params(folder: Path) -> tuple[Intrinsics, float, Path] | None:
    """The intrinsics and depth scale of a ``cam_params.json`` in ``folder`` or beside it."""
    path = next((p for p in (folder / CAM_PARAMS, folder.parent / CAM_PARAMS) if p.is_file()),
                None)
    if path is None:
        return None
    try:
        cam = json.loads(path.read_text())["camera"]
        w, h = (int(_number(cam[k], f"{path} camera.{k}")) for k in ("w", "h"))
        intr = check_intrinsics([cam[k] for k in ("fx", "fy", "cx", "cy")], f"{path} camera")
        scale = check_depth_scale(cam["scale"], f"{path} camera.scale")
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise ValueError(f"{path}: expected {{\"camera\": {{\"w\", \"h\", \"fx\", \"fy\", "
                         f"\"cx\", \"cy\", \"scale\"}}}} ({type(err).__name__}: {err})") from err
    if w <= 0 or h <= 0:
        raise ValueError(f"{path}: camera.w and camera.h must be > 0, got {w} x {h}")
    return intr._replace(width=w, height=h), scale, path


def _given(intrinsics, depth_scale):
    return (None if intrinsics is None else check_intrinsics(intrinsics),
            None if depth_scale is None else check_depth_scale(depth_scale))


def replica_calibration(folder: Path, intrinsics=None, depth_scale=None):
    """``(Intrinsics, depth scale, provenance)`` of a Replica folder (module docstring)."""
    intrinsics, depth_scale = _given(intrinsics, depth_scale)
    found = cam_params(folder)
    intr_from = scale_from = "Replica default (no cam_params.json)"
    if found:
        intr_from = scale_from = str(found[2])
    intr = intrinsics or (found[0] if found else REPLICA_INTRINSICS)
    scale = depth_scale or (found[1] if found else REPLICA_DEPTH_SCALE)
    return intr, scale, provenance(intr, "--intrinsics" if intrinsics else intr_from,
                                   scale, "--depth-scale" if depth_scale else scale_from)


def tum_preset(folder: Path) -> str | None:
    """``"fr1"``, ``"fr2"`` or ``"fr3"`` when the folder's name names a Freiburg sensor."""
    match = re.search(r"(?:freiburg|fr)([123])(?!\d)", folder.resolve().name.lower())
    return f"fr{match.group(1)}" if match else None


def tum_calibration(folder: Path, intrinsics=None, depth_scale=None):
    """``(Intrinsics, depth scale, provenance)`` of a TUM folder (module docstring)."""
    intrinsics, depth_scale = _given(intrinsics, depth_scale)
    preset = tum_preset(folder)
    intr_from = (f"TUM {preset} preset (folder name)" if preset else
                 "TUM fr1 preset (default: the folder name names no freiburg1/2/3; "
                 "give --intrinsics otherwise)")
    intr = intrinsics or TUM_PRESETS[preset or "fr1"]
    scale = depth_scale or TUM_DEPTH_SCALE
    return intr, scale, provenance(intr, "--intrinsics" if intrinsics else intr_from, scale,
                                   "--depth-scale" if depth_scale else "TUM default")


def provenance(intr: Intrinsics | None, intr_from: str, scale: float | None,
               scale_from: str) -> dict:
    """What a run's record says about its intrinsics and depth scale."""
    out = {"intrinsics_from": intr_from, "depth_scale": scale, "depth_scale_from": scale_from}
    if intr is not None:
        out["intrinsics_given"] = [intr.fx, intr.fy, intr.cx, intr.cy]
    return out
