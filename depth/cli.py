"""``python -m depth``: RGB frames -> 16-bit millimetre depth PNGs with an ONNX model.

    python -m depth --model M.onnx --input FRAMES_DIR --output DEPTH_DIR \\
        [--preset depth-anything] [--reference FIRST_DEPTH.png --align scale-shift-inverse]

Writes ``DEPTH_DIR/<frame stem>.png`` (depth * 1000 as uint16, 0 = missing) and
``DEPTH_DIR/_preview.png``. Relative or inverse models are turned into metric depth
by aligning their prediction to reference sensor depth (a file for the first frame,
or a folder matched by file stem); one alignment for the whole sequence by default.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from depth.align import DEFAULT_METHOD, IDENTITY, METHODS, Alignment, align, apply, select
from depth.onnx_depth import DEFAULT_BATCH_SIZE, OnnxDepth
from depth.presets import KINDS, PRESETS
from depth.preview import preview_indices, save_preview
from vbgs.data.depth_png import MILLIMETRES, read_depth_png, write_depth_png
from vbgs.data.images import read_rgb

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
PREVIEW_NAME = "_preview.png"
UINT16_MAX = float(np.iinfo(np.uint16).max)
SCOPES = ("global", "per-frame")
MIN_KEPT_FRACTION = 0.5  # a frame keeping fewer valid depth pixels than this is warned about
DESCRIPTION = "RGB frames -> 16-bit millimetre depth PNGs with a user-supplied ONNX depth model."


class CliError(Exception):
    """A user-facing problem: printed as ``error: ...`` with exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m depth", description=DESCRIPTION)
    ap.add_argument("--model", required=True, type=Path, help="ONNX depth model (.onnx)")
    ap.add_argument("--input", required=True, type=Path, help="folder of RGB frames")
    ap.add_argument("--output", required=True, type=Path, help="folder for depth PNGs")
    ap.add_argument("--preset", choices=sorted(PRESETS), help="model family preprocessing")
    ap.add_argument("--kind", choices=KINDS, help="what the model outputs (default: preset's)")
    ap.add_argument("--input-size", type=int, help="model input shorter side (or square side)")
    ap.add_argument("--align", choices=METHODS,
                    help="alignment to --reference (default: by kind; none for metric)")
    ap.add_argument("--align-scope", choices=SCOPES, default="global",
                    help="one alignment for all frames, or one per frame with a reference")
    ap.add_argument("--reference", type=Path,
                    help="sensor depth PNG (the first frame's) or a folder matched by stem")
    ap.add_argument("--reference-fraction", type=float, default=1.0,
                    help="fraction of valid reference pixels used for alignment")
    ap.add_argument("--reference-scale", type=float, default=MILLIMETRES,
                    help="reference PNG units per metre (1000 = mm)")
    ap.add_argument("--depth-scale", type=float, default=MILLIMETRES,
                    help="output PNG units per metre (1000 = mm)")
    ap.add_argument("--batch-size", type=int, default=DEFAULT_BATCH_SIZE)
    ap.add_argument("--providers", default=None, help="e.g. cuda,cpu (default cpu)")
    ap.add_argument("--seed", type=int, default=0, help="seed for subsampling and RANSAC starts")
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return ap


def list_frames(folder: Path) -> list[Path]:
    """Image files in ``folder``, sorted by name; refuses a missing or empty folder."""
    if not folder.is_dir():
        raise CliError(f"input folder not found: {folder}")
    frames = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not frames:
        raise CliError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in input folder {folder}")
    if any(p.stem + ".png" == PREVIEW_NAME for p in frames):
        raise CliError(f"a frame is named like the preview {PREVIEW_NAME}; rename it")
    return frames


def read_frame(path: Path) -> np.ndarray:
    """An input frame as float32 RGB ``[h, w, 3]`` in [0, 1] (alpha dropped); a file
    that cannot be used is a :class:`CliError` naming it."""
    try:
        return read_rgb(path)
    except (OSError, TypeError, ValueError) as err:
        raise CliError(str(err)) from err


def check_apart(inputs: Path, output: Path) -> None:
    """Refuse an output folder equal to or inside the input folder: depth PNGs named
    like the frames would overwrite them (or be read back as frames next time)."""
    src, dst = Path(inputs).resolve(), Path(output).resolve()
    if dst == src or src in dst.parents:
        raise CliError(f"--output {output} is {'the' if dst == src else 'inside the'} "
                       f"--input folder {inputs}: the depth PNGs would overwrite or mix with "
                       f"the frames; give a folder outside it")


def check_output_folder(folder: Path) -> None:
    """Refuse, before any work, an output path that is a file, lies under a file, or
    cannot be written. The folder itself is created by the first write."""
    if folder.exists() and not folder.is_dir():
        raise CliError(f"--output {folder} is a file, not a folder; give a folder for the "
                       "depth PNGs (it is created if missing)")
    ancestor = next(a for a in (folder, *folder.parents) if a.exists())
    if not ancestor.is_dir():
        raise CliError(f"--output {folder}: {ancestor} is a file, not a folder")
    if not os.access(ancestor, os.W_OK):
        raise CliError(f"--output {folder}: no permission to write in {ancestor}")


def valid_pixels(depth: np.ndarray, max_depth: float) -> np.ndarray:
    """Pixels a depth PNG can store: finite, > 0 and at most ``max_depth`` (bool ``[h, w]``)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0) & (depth <= max_depth)


def _nothing_valid(name: str, pred: np.ndarray, max_depth: float, args) -> CliError:
    """The refusal of a first frame without one storable depth pixel; ``pred`` is the raw
    model output, whose range shows what went wrong."""
    pred = np.asarray(pred)
    finite = pred[np.isfinite(pred)]
    spans = (f"the model's output spans {finite.min():.4g} to {finite.max():.4g}" if finite.size
             else "the model's output is all NaN/inf")
    return CliError(
        f"{name}: no pixel has valid depth (0 of {pred.size} kept: <= 0, NaN or beyond "
        f"{max_depth:.6g} at --depth-scale {args.depth_scale:g}; {spans}); check --kind "
        f"(inverse and relative models need --reference and --align) and --depth-scale; "
        f"nothing was written")


def reference_paths(reference: Path, frames: list[Path]) -> dict[str, Path]:
    """Reference depth PNG per frame stem: a folder matched by stem, or one file that
    belongs to the frame with its stem, else to the first frame."""
    stems = [p.stem for p in frames]
    if reference.is_file():
        return {reference.stem if reference.stem in stems else stems[0]: reference}
    if not reference.is_dir():
        raise CliError(f"reference depth not found: {reference}")
    found = {p.stem: p for p in reference.glob("*.png") if p.stem in stems}
    if not found:
        raise CliError(f"no PNG in {reference} shares a name with a frame in the input folder")
    return found


def reference_pixels(depth: np.ndarray, fraction: float, rng) -> np.ndarray:
    """Flat indices of a seeded random ``fraction`` of the valid (> 0) reference pixels."""
    valid = np.flatnonzero(depth.ravel() > 0)
    keep = max(1, int(round(fraction * len(valid)))) if len(valid) else 0
    return np.sort(rng.choice(valid, keep, replace=False)) if keep < len(valid) else valid


def choose_method(kind: str, method: str | None, has_reference: bool) -> str:
    method = method or (DEFAULT_METHOD[kind] if has_reference else "none")
    if method != "none" and not has_reference:
        raise CliError(f"--align {method} needs --reference sensor depth")
    if method == "none" and kind != "metric":
        raise CliError(
            f"--kind {kind} predictions are not metric depth; pass --reference sensor depth and "
            f"--align {DEFAULT_METHOD[kind]} (or --kind metric if the model is metric)"
        )
    return method


def fit_alignments(model: OnnxDepth, frames: list[Path], refs: dict[str, Path], method: str,
                   args) -> tuple[Alignment, dict[str, Alignment]]:
    """The global alignment (pooled over all reference frames) and per-frame ones."""
    space = "inverse" if model.kind == "inverse" else "depth"
    rng = np.random.default_rng(args.seed)
    pooled_p, pooled_d, per_frame = [], [], {}
    for path in frames:
        if path.stem not in refs:
            continue
        rgb = read_frame(path)
        try:
            ref = read_depth_png(refs[path.stem], scale=args.reference_scale)
        except (ValueError, FileNotFoundError) as err:
            raise CliError(f"reference depth: {err}") from err
        if ref.shape != rgb.shape[:2]:
            raise CliError(
                f"reference {refs[path.stem]} is {ref.shape}, frame {path} is {rgb.shape[:2]}; "
                "they must have the same size"
            )
        pred = model.predict(rgb)
        idx = reference_pixels(ref, args.reference_fraction, rng)
        p, d = select(pred, ref, idx)
        pooled_p.append(p)
        pooled_d.append(d)
        if args.align_scope == "per-frame":
            per_frame[path.stem] = _align_or_explain(p, d, method, space, args.seed, path.name)
    fit = _align_or_explain(np.concatenate(pooled_p), np.concatenate(pooled_d), method, space,
                            args.seed, f"{len(pooled_p)} reference frame(s)")
    return fit, per_frame


def _align_or_explain(p, d, method, space, seed, where) -> Alignment:
    try:
        return align(p, d, None, method, space=space, seed=seed)
    except ValueError as err:
        raise CliError(f"alignment on {where} failed: {err}") from err


def _batches(items: list, size: int):
    for start in range(0, len(items), size):
        yield items[start:start + size]


# A model input side under this many pixels leaves the network nothing to see: it gives
# one depth for the whole frame.
MIN_INPUT_SIDE = 8


def check_numbers(args) -> None:
    """The scales (PNG codes per scene unit) finite and > 0; an input side of at least
    MIN_INPUT_SIDE pixels."""
    for flag, value, of in (("--depth-scale", args.depth_scale, "written depth PNGs"),
                            ("--reference-scale", args.reference_scale, "the reference's "
                                                                         "depth PNGs")):
        if not (np.isfinite(value) and value > 0):
            raise CliError(f"{flag} must be a finite number > 0 (codes per scene unit of "
                           f"{of}: 1000 for millimetres, 5000 for TUM), got {value:g}")
    if args.input_size is not None and args.input_size < MIN_INPUT_SIDE:
        raise CliError(f"--input-size must be at least {MIN_INPUT_SIDE} pixels (the model "
                       f"input's shorter side), got {args.input_size}: smaller leaves the "
                       f"network nothing to see and gives one depth for the whole frame")


def run(args) -> dict:
    """Run the CLI on parsed arguments; returns the summary it prints."""
    from tqdm import tqdm

    if not args.model.is_file():
        raise CliError(f"ONNX model not found: {args.model} (weights are not shipped; export or "
                       "download a depth model to .onnx and pass its path)")
    if not 0.0 < args.reference_fraction <= 1.0:
        raise CliError(f"--reference-fraction must be in (0, 1], got {args.reference_fraction}")
    check_numbers(args)
    check_output_folder(args.output)
    check_apart(args.input, args.output)
    frames = list_frames(args.input)
    try:
        model = OnnxDepth(args.model, kind=args.kind, preset=args.preset,
                          providers=args.providers, input_size=args.input_size,
                          batch_size=args.batch_size)
    except (ValueError, FileNotFoundError) as err:
        raise CliError(str(err)) from err
    refs = reference_paths(args.reference, frames) if args.reference else {}
    method = choose_method(model.kind, args.align, bool(refs))
    fit, per_frame = fit_alignments(model, frames, refs, method, args) if refs else (IDENTITY, {})
    max_depth = UINT16_MAX / args.depth_scale
    show = set(preview_indices(len(frames)))
    shown, out_of_range, written, kept, total, sparse = [], 0, 0, 0, 0, []
    start = time.perf_counter()
    try:
        with tqdm(total=len(frames), unit="frame", disable=args.no_progress) as bar:
            for chunk in _batches(list(enumerate(frames)), model.batch_size):
                rgbs = [read_frame(path) for _, path in chunk]
                same = len({r.shape for r in rgbs}) == 1
                try:  # a model whose output is no depth map (3 channels) fails here
                    preds = model.predict(rgbs) if same else [model.predict(r) for r in rgbs]
                except ValueError as err:
                    raise CliError(f"{err}; {written} of {len(frames)} depth PNGs written "
                                   f"to {args.output}") from err
                for (i, path), rgb, pred in zip(chunk, rgbs, preds, strict=True):
                    depth = apply(per_frame.get(path.stem, fit), pred)
                    ok = valid_pixels(depth, max_depth)
                    if i == 0 and not ok.any():  # refused before anything is written
                        raise _nothing_valid(path.name, pred, max_depth, args)
                    with np.errstate(invalid="ignore"):
                        too_far = depth > max_depth
                    out_of_range += int(too_far.sum())
                    depth = np.where(ok, depth, 0.0)  # stored as missing, never wrapped
                    kept, total = kept + int(ok.sum()), total + ok.size
                    if ok.sum() < MIN_KEPT_FRACTION * ok.size:
                        sparse.append((path.name, int(ok.sum()), ok.size))
                    write_depth_png(args.output / f"{path.stem}.png", depth,
                                    scale=args.depth_scale)
                    written += 1
                    if i in show:
                        shown.append((rgb, depth, path.name))
                    bar.update(1)
    except KeyboardInterrupt:
        raise KeyboardInterrupt(f"{written} of {len(frames)} depth PNGs written to "
                                f"{args.output}, each complete") from None
    elapsed = time.perf_counter() - start
    preview = save_preview(args.output / PREVIEW_NAME, *map(list, zip(*shown, strict=True)))
    return {"frames": written, "seconds": elapsed, "fps": written / max(elapsed, 1e-9),
            "method": method, "scope": args.align_scope, "alignment": fit,
            "per_frame": per_frame, "reference_frames": len(refs),
            "out_of_range_pixels": out_of_range, "output": args.output, "preview": preview,
            "kept_pixels": kept, "pixels": total, "sparse_frames": sparse,
            "max_depth": max_depth}


def format_summary(s: dict) -> str:
    a = s["alignment"]
    lines = [f"depth: {s['frames']} frames in {s['seconds']:.2f} s ({s['fps']:.1f} fps, "
             f"read + predict + write) -> {s['output']}"]
    if s["method"] == "none" and not s["reference_frames"]:
        lines.append("alignment: none (metric model)")
    else:
        lines.append(
            f"alignment: {s['method']} ({s['scope']}, {s['reference_frames']} reference frame(s), "
            f"{a.n_points} px): scale={a.scale:.6g} shift={a.shift:.6g} space={a.space} "
            f"residual={100 * a.residual:.2f}% inliers={100 * a.inlier_fraction:.1f}%")
    lines.append(f"valid depth: {s['kept_pixels']} of {s['pixels']} pixels kept "
                 f"({100 * s['kept_pixels'] / max(s['pixels'], 1):.1f}%)")
    if s["out_of_range_pixels"]:
        lines.append(f"out of 16-bit range: {s['out_of_range_pixels']} pixels stored as missing")
    lines.append(f"preview: {s['preview']}")
    return "\n".join(lines)


def sparse_warning(s: dict) -> str | None:
    """One line when some frames kept under MIN_KEPT_FRACTION of their pixels, else None."""
    if not s["sparse_frames"]:
        return None
    name, kept, size = min(s["sparse_frames"], key=lambda f: f[1] / f[2])
    return (f"warning: {len(s['sparse_frames'])} of {s['frames']} frames kept valid depth at "
            f"under {100 * MIN_KEPT_FRACTION:.0f}% of their pixels (worst {name}: {kept} of "
            f"{size}); the model gave depth <= 0, NaN or beyond {s['max_depth']:.6g} there, "
            f"stored as missing: check --kind, --align and --depth-scale")


def main(argv: list[str] | None = None) -> int:
    """Exit status: 0 done, 2 refused (one ``error:`` line), 130 interrupted (one line)."""
    try:
        args = build_parser().parse_args(argv)
        summary = run(args)
    except CliError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # a write that failed (disk full, permissions): name the file
        print(f"error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as err:
        print(f"interrupted{f': {err}' if str(err) else ''}", file=sys.stderr)
        return 130
    print(format_summary(summary))
    warning = sparse_warning(summary)
    if warning:
        print(warning, file=sys.stderr)
    return 0
