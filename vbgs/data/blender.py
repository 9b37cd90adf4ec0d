"""The Blender / NeRF-synthetic layout: loader and writer.

A folder holds ``transforms_train.json`` and ``transforms_test.json`` (or, for
the test split, ``transforms_val.json``), each with

* ``camera_angle_x``: horizontal field of view in radians (``camera_angle_y``
  optional); or ``fl_x, fl_y, cx, cy`` in pixels, with pixel centres at
  ``col + 0.5`` as nerfstudio writes them (these win when present);
* ``frames[].file_path``: image path relative to the folder, with or without the
  ``.png`` extension (``./train/r_0``);
* ``frames[].transform_matrix``: 4x4 camera-to-world in OpenGL/Blender camera
  axes (x right, y up, z backward), converted to OpenCV axes on loading.

Validation views (``Scene.val``, where render settings are tuned; test views only
report) are ``transforms_val.json`` when the folder has it beside
``transforms_test.json``; otherwise (no val file, or the val file serves as the test
split) every ``val_every``-th training frame is held out of training as a validation
view (:func:`~vbgs.data.scene.hold_out_validation`), so the stream is that much shorter.

Intrinsics in pixels refer to a ``w x h`` image (keys ``w``, ``h``); a frame may
override any intrinsic key (as nerfstudio writes them). Each frame's camera is
scaled from ``w x h`` to its own image size, so frames of different sizes in one
split get consistent intrinsics; without ``w``/``h``, pixel intrinsics refer to the
split's first image and a frame of another size is refused (its scale is unknown).
Angles need no size: ``f = 0.5 * width / tan(0.5 * camera_angle_x)``.

RGBA images are composited onto ``background`` (white by default, as for
NeRF-synthetic). Depth sits beside each image, named after it: for
``train/r_0.png`` either ``train/r_0_depth.png`` (16-bit, millimetres, 0 =
missing) or ``train/r_0_depth.npy`` (float z-depth in metres, 0/NaN = missing);
the PNG wins if both exist. (The ``r_0_depth_0000.png`` maps shipped with
NeRF-synthetic's test split are 8-bit and not metric; they are not read.)
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from skimage import io as skio

from vbgs.data.calibration import check_depth_scale, provenance
from vbgs.data.calibration import check_intrinsics as given_intrinsics
from vbgs.data.depth_png import MILLIMETRES, fits_depth_png, read_depth_png, write_depth_png
from vbgs.data.images import read_rgb
from vbgs.data.scene import (
    Frame,
    Scene,
    bounds_from_frames,
    hold_out_validation,
    require_some_depth,
    resize_frame,
    select,
    validate_frame,
)
from vbgs.io_atomic import write_atomic, write_text_atomic
from vbgs.render.camera import Camera, opengl_to_opencv

BLENDER_BACKGROUND = (1.0, 1.0, 1.0)
VAL_EVERY = 8  # without transforms_val.json, every 8th training frame is a validation view
_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def _depth_beside(image: Path, depth_scale: float, require: bool, shape) -> np.ndarray:
    stem = image.with_suffix("") if image.suffix.lower() in _IMAGE_SUFFIXES else image
    png, npy = Path(f"{stem}_depth.png"), Path(f"{stem}_depth.npy")
    if png.is_file():
        return read_depth_png(png, depth_scale)
    if npy.is_file():
        depth = np.asarray(np.load(npy), np.float64)
        with np.errstate(invalid="ignore"):
            return np.where(np.isfinite(depth) & (depth > 0), depth, 0.0).astype(np.float32)
    if require:
        raise FileNotFoundError(
            f"no depth for {image}: expected {png.name} (16-bit, millimetres) or {npy.name} "
            f"(metres) beside it; for an RGB-only folder give fit-scene --depth-model "
            f"MODEL.onnx (depth estimated as frames arrive), or write depth files with "
            f"`python -m depth` (in code: load_blender(..., require_depth=False))"
        )
    return np.zeros(shape, np.float32)


INTRINSIC_KEYS = ("camera_angle_x", "camera_angle_y", "fl_x", "fl_y", "cx", "cy", "w", "h")
PIXEL_KEYS = ("fl_x", "fl_y", "cx", "cy")  # in pixels of a w x h image


def _intrinsics(meta: dict, entry: dict) -> dict:
    """The intrinsics of one frame: the file's, overridden by the frame's own (nerfstudio)."""
    return {k: entry.get(k, meta.get(k)) for k in INTRINSIC_KEYS if entry.get(k, meta.get(k))
            is not None}


def check_intrinsics(intr: dict, what: str) -> dict:
    """Refuse intrinsics a camera cannot have, naming the key and the likely fix: text
    instead of numbers, a field of view in degrees, zero or negative focal lengths or
    sizes; and a file with neither ``camera_angle_x`` nor a positive ``fl_x``."""
    for key, value in intr.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{what}: {key!r} is {value!r}, not a number; write it without "
                             f"quotes")
        if not np.isfinite(value):
            raise ValueError(f"{what}: {key!r} is {value!r}; give a finite number")
    for key in ("camera_angle_x", "camera_angle_y"):
        angle = intr.get(key)
        if angle is not None and not 0 < angle < np.pi:
            hint = (f"; in degrees? {angle} degrees is {np.deg2rad(angle):.4f} rad"
                    if np.pi <= angle < 180 else "")
            raise ValueError(f"{what}: {key!r} is {angle}: a field of view in radians lies "
                             f"in (0, pi){hint}")
    for key in ("w", "h", "fl_y"):
        if key in intr and intr[key] <= 0:
            raise ValueError(f"{what}: {key!r} is {intr[key]}; it must be > 0 (pixels)")
    if not intr.get("fl_x", 0) > 0 and "camera_angle_x" not in intr:
        given = f"'fl_x' is {intr['fl_x']}" if "fl_x" in intr else "neither is given"
        raise ValueError(f"{what}: needs 'camera_angle_x' (radians) or a positive 'fl_x' "
                         f"(pixels); {given}")
    return intr


def _camera(intr: dict, width: int, height: int, ref_size, pose_gl: np.ndarray) -> Camera:
    """Camera for a ``width x height`` image.

    Angles give ``f = 0.5 * side / tan(0.5 * angle)`` at the image's own size. Pixel
    intrinsics refer to a ``w x h`` image (``ref_size`` when the file has no ``w``,
    ``h``) and are scaled per axis to this image: ``fx, cx`` by ``width / w``, ``fy, cy``
    by ``height / h`` (pixel edges scale exactly; centres sit at ``col + 0.5``).
    """
    ref_w, ref_h = intr.get("w", ref_size[0]), intr.get("h", ref_size[1])
    sx, sy = width / float(ref_w), height / float(ref_h)
    if intr.get("fl_x"):
        fx = intr["fl_x"] * sx
    else:
        fx = 0.5 * width / np.tan(0.5 * intr["camera_angle_x"])
    if intr.get("fl_y"):
        fy = intr["fl_y"] * sy
    elif "camera_angle_y" in intr:
        fy = 0.5 * height / np.tan(0.5 * intr["camera_angle_y"])
    else:
        fy = intr["fl_x"] * sy if intr.get("fl_x") else fx
    cx = intr["cx"] * sx if "cx" in intr else width / 2.0
    cy = intr["cy"] * sy if "cy" in intr else height / 2.0
    return Camera(
        float(fx), float(fy), float(cx), float(cy), width, height, opengl_to_opencv(pose_gl)
    )


def _reference_size(intr: dict, width: int, height: int, first, what: str):
    """The size pixel intrinsics refer to when the file gives no ``w``/``h``: the split's
    first image, so a frame of another size is refused (its scale is unknown)."""
    if ("w" in intr and "h" in intr) or not any(k in intr for k in PIXEL_KEYS):
        return first or (width, height)
    if first is not None and first != (width, height):
        given = ", ".join(k for k in PIXEL_KEYS if k in intr)
        raise ValueError(
            f"{what}: image is {width}x{height} but the split's first image is "
            f"{first[0]}x{first[1]}, and the intrinsics ({given}) "
            f"are in pixels without 'w' and 'h'; add \"w\" and \"h\" (the image size they "
            f"refer to) to the transforms file, or give every image the same size"
        )
    return first or (width, height)


def _refuse_scale_for_npy(train_json: Path, depth_scale: float) -> None:
    """A depth scale given for a folder whose training depth is all ``.npy`` (float depth
    in scene units, no codes to scale) would be recorded as used and change nothing."""
    pngs = list(train_json.parent.rglob("*_depth.png"))
    npys = list(train_json.parent.rglob("*_depth.npy"))
    if npys and not pngs:
        raise ValueError(f"--depth-scale {depth_scale:g} converts 16-bit PNG depth codes to "
                         f"scene units, but {train_json.parent}'s depth is {len(npys)} .npy "
                         f"file(s) (float depth in scene units, read as they are): drop "
                         f"--depth-scale, or rescale the .npy files")


def _load_split(path: Path, keep, size, background, depth_scale, require_depth,
                intrinsics=None) -> list[Frame]:
    """Frames of one transforms file; ``keep(n)`` gives the frame indices to read."""
    try:
        meta = json.loads(path.read_text())
        entries = list(meta["frames"])
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise ValueError(f"{path}: not a transforms file with a 'frames' list ({err})") from err
    frames, first = [], None
    for i in keep(len(entries)):
        entry, what = entries[i], f"{path.name} frame {i}"
        if (
            not isinstance(entry, dict)
            or "file_path" not in entry
            or "transform_matrix" not in entry
        ):
            raise ValueError(f"{what}: needs 'file_path' and 'transform_matrix'")
        base = path.parent / entry["file_path"]
        if base.suffix.lower() in _IMAGE_SUFFIXES:
            candidates = [base]
        else:
            candidates = [Path(f"{base}.png"), Path(f"{base}.jpg"), base]
        image = next((c for c in candidates if c.is_file()), None)
        if image is None:
            raise FileNotFoundError(
                f"{what}: image {entry['file_path']!r} not found (looked for {candidates[0]})"
            )
        rgb = read_rgb(image, background=background)  # [h, w, 3]
        pose_gl = np.asarray(entry["transform_matrix"], np.float64)
        if pose_gl.shape != (4, 4):
            raise ValueError(f"{what}: transform_matrix must be 4x4, got shape {pose_gl.shape}")
        if not np.isfinite(pose_gl).all():
            raise ValueError(f"{what}: transform_matrix has {int((~np.isfinite(pose_gl)).sum())} "
                             f"NaN/inf entries; fix this frame's pose in {path.name}")
        height, width = rgb.shape[:2]
        if intrinsics is not None:  # given by the caller: the file's are not read
            cam = intrinsics.camera(width, height, opengl_to_opencv(pose_gl))
        else:
            intr = check_intrinsics(_intrinsics(meta, entry), f"{path.name} ({what})")
            first = _reference_size(intr, width, height, first, f"{what} ({image.name})")
            cam = _camera(intr, width, height, first, pose_gl)
        depth = _depth_beside(image, depth_scale, require_depth, rgb.shape[:2])
        frame = validate_frame(Frame(rgb, depth, cam), f"{what} ({image})")
        frames.append(resize_frame(require_some_depth(frame, f"{what} ({image})")
                                   if require_depth else frame, size))
    return frames


def load_blender(
    folder,
    size=None,
    max_frames: int | None = None,
    stride: int = 1,
    max_test: int | None = None,
    background=BLENDER_BACKGROUND,
    depth_scale: float | None = None,
    require_depth: bool = True,
    max_val: int | None = None,
    val_every: int | None = VAL_EVERY,
    intrinsics=None,
) -> Scene:
    """Load a Blender/NeRF-synthetic folder (see the module docstring).

    size: resize (see :func:`~vbgs.data.scene.target_size`); stride, max_frames:
    thin the training split; max_test: cap the test split; max_val: cap the
    validation split; val_every: without a separate ``transforms_val.json``, hold out
    every val_every-th training frame for validation (None: no validation views);
    depth_scale: PNG
    depth codes per scene unit (None: millimetres); require_depth: raise if a frame has no depth
    file (else its depth is all 0); intrinsics: ``fx, fy, cx, cy`` (pixels of the images
    as stored, centres at integers) instead of the file's. Bounds come from the
    training depth.
    """
    folder = Path(folder)
    depth_from = "Blender default (millimetres)" if depth_scale is None else "--depth-scale"
    depth_scale = MILLIMETRES if depth_scale is None else check_depth_scale(depth_scale)
    intrinsics = None if intrinsics is None else given_intrinsics(intrinsics)
    calibration = provenance(intrinsics, "--intrinsics" if intrinsics else
                             "transforms_*.json", depth_scale, depth_from)
    train_json = folder / "transforms_train.json"
    if not train_json.is_file():
        raise FileNotFoundError(f"{train_json} not found: a Blender dataset needs this file")
    tests = [folder / "transforms_test.json", folder / "transforms_val.json"]
    test_json = next((p for p in tests if p.is_file()), None)
    if test_json is None:
        raise FileNotFoundError(f"{folder}: neither {tests[0].name} nor {tests[1].name} found")
    background = tuple(float(c) for c in background)
    args = (size, background, depth_scale, require_depth, intrinsics)
    if depth_from == "--depth-scale":
        _refuse_scale_for_npy(train_json, depth_scale)
    train = _load_split(train_json, lambda n: select(n, stride, max_frames), *args)
    test = _load_split(test_json, lambda n: list(range(n))[:max_test], *args)
    val_json = folder / "transforms_val.json"
    if val_json.is_file() and val_json != test_json:
        val = _load_split(val_json, lambda n: list(range(n))[:max_val], *args)
    else:
        train, val = hold_out_validation(train, val_every)
        val = val[:max_val]
    return Scene(folder.name, train, test, bounds_from_frames(train), background, val,
                 calibration)


DEPTH_FILES = ("png", "npy", "auto")  # write_blender's depth files; auto: png where all fit


def write_blender(scene: Scene, folder, progress=None, depth: str = "png") -> Path:
    """Write ``scene`` in the Blender layout that :func:`load_blender` reads; return the folder.

    Files: ``train/r_000.png`` (8-bit RGB), ``train/r_000_depth.png`` (16-bit mm,
    0 = missing), the same under ``test/`` (and ``val/`` when the scene has validation
    views), and ``transforms_train.json`` / ``transforms_test.json`` (/
    ``transforms_val.json``) with ``camera_angle_x``, ``fl_x, fl_y, cx, cy, w, h``
    and per-frame ``transform_matrix`` in OpenGL axes. Colour is quantised to
    1/255 and depth to 1 mm; depth beyond 65.535 scene units is refused. ``depth="npy"``
    writes ``r_000_depth.npy`` instead (float32 metres, exact, any range; a PNG of the
    same name is removed: the loader would prefer it); ``"auto"``: PNGs when every
    frame's depth fits them, else npy for all. The transforms files are written last,
    so an interrupted write leaves a folder the loader refuses. ``progress(items,
    total)`` wraps the loop over the frames (a bar).
    """
    folder = Path(folder)
    splits = [("train", scene.train), ("test", scene.test)] + ([("val", scene.val)]
                                                               if scene.val else [])
    metas = {split: _split_meta(split, frames) for split, frames in splits}
    items = [(split, i, f) for split, frames in splits for i, f in enumerate(frames)]
    depth = depth_files(scene, depth)
    for split, i, f in (items if progress is None else progress(items, len(items))):
        (folder / split).mkdir(parents=True, exist_ok=True)
        stem = f"{split}/r_{i:03d}"
        rgb8 = np.round(np.clip(f.rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
        write_atomic(folder / f"{stem}.png",
                     lambda tmp, rgb8=rgb8: skio.imsave(tmp, rgb8, check_contrast=False))
        if depth == "png":
            write_depth_png(folder / f"{stem}_depth.png", f.depth, MILLIMETRES)
        else:
            (folder / f"{stem}_depth.png").unlink(missing_ok=True)
            write_atomic(folder / f"{stem}_depth.npy",
                         lambda tmp, d=np.asarray(f.depth, np.float32): np.save(tmp, d))
        pose_gl = opengl_to_opencv(f.camera.pose)  # the axis flip is its own inverse
        metas[split]["frames"].append({"file_path": f"./{stem}",
                                       "transform_matrix": pose_gl.tolist()})
    for split, meta in metas.items():
        (folder / split).mkdir(parents=True, exist_ok=True)
        write_text_atomic(folder / f"transforms_{split}.json", json.dumps(meta, indent=2))
    if not scene.val:  # an earlier write's validation split would be read as this scene's
        (folder / "transforms_val.json").unlink(missing_ok=True)
    return folder


def depth_files(scene: Scene, depth: str = "auto") -> str:
    """``"png"`` or ``"npy"``: the depth files :func:`write_blender` writes for ``depth``
    (``"auto"``: PNGs when every frame's depth fits 16-bit millimetres)."""
    if depth not in DEPTH_FILES:
        raise ValueError(f"depth files {depth!r}: use one of {', '.join(DEPTH_FILES)}")
    if depth != "auto":
        return depth
    frames = [*scene.train, *scene.test, *scene.val]
    return "png" if all(fits_depth_png(f.depth, MILLIMETRES) for f in frames) else "npy"


def _split_meta(split: str, frames: list[Frame]) -> dict:
    """A split's transforms file without its frames: the one camera of its frames."""
    cams = {(f.camera.fx, f.camera.fy, f.camera.cx, f.camera.cy) + f.rgb.shape[1::-1]
            for f in frames}  # fmt: skip
    if len(cams) > 1:
        raise ValueError(
            f"write_blender: {split} frames have {len(cams)} different intrinsics or sizes; "
            f"the Blender layout stores one camera per split (resize the frames first)"
        )
    meta: dict = {"frames": []}
    if frames:
        fx, fy, cx, cy, w, h = (float(x) for x in cams.pop())
        meta.update(
            camera_angle_x=2 * float(np.arctan(0.5 * w / fx)),
            fl_x=fx, fl_y=fy, cx=cx, cy=cy, w=int(w), h=int(h),
        )  # fmt: skip
    return meta
