"""Printing results and errors the same way for every command, and the one JSON writer
(:func:`dumps`): strict JSON, a number that is not finite (a PSNR of +inf when the render
equals its target, NaN where nothing was measured) ``null`` with a reason beside it
(``"psnr": null, "psnr_note": "..."``), so strict parsers (JavaScript's ``JSON.parse``,
``jq``) read every line."""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np

# Keys shown first in the human-readable summary, when present.
_HEADLINE = ("psnr", "ssim", "depth_l1", "seconds", "seconds_per_frame", "components_used",
             "peak_memory_mb")


def fail(err: Exception, as_json: bool = False) -> int:
    """A user-facing error: one line on stderr, exit status 2, no traceback; with
    ``as_json`` also one JSON object with an ``error`` field on stdout (a caller that
    parses the last line of stdout gets the failure, not nothing)."""
    print(f"error: {err}", file=sys.stderr)
    if as_json:
        print(dumps({"error": str(err), "error_type": type(err).__name__}))
    return 2


INTERRUPTED = 130  # exit status after Ctrl-C (128 + SIGINT), as shells report it


def interrupted(err: KeyboardInterrupt | None = None) -> int:
    """Ctrl-C: one line on stderr (what was kept, when known), exit status 130."""
    detail = str(err) if err is not None else ""
    print(f"interrupted{f': {detail}' if detail else ''}", file=sys.stderr)
    return INTERRUPTED


def check_output_file(path: str | None, flag: str, suffix: str) -> Path | None:
    """Check an output file path before any work starts; create its folder.

    Refuses a path that is a folder, one whose name does not end in ``suffix`` (a
    writer would add its own and write somewhere else), and one under a file or in a
    folder that cannot be written. Returns the path (None when not given).
    """
    if path is None:
        return None
    out = Path(path)
    if out.is_dir():
        raise ValueError(f"{flag} {path} is a folder; give a file name ending in {suffix}")
    if out.suffix.lower() != suffix:
        raise ValueError(f"{flag} {path}: the file name must end in {suffix}")
    parent = out.parent
    ancestor = next(a for a in (parent, *parent.parents) if a.exists())
    if not ancestor.is_dir():
        raise ValueError(f"{flag} {path}: {ancestor} is a file, not a folder")
    parent.mkdir(parents=True, exist_ok=True)
    if not os.access(parent, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise ValueError(f"{flag} {path}: no permission to write there")
    return out


def check_fewer_components(components: int, points: int, what: str, fix: str) -> None:
    """Refuse at least as many components as data points: each point could get its own
    component, so the fit is trivially exact and its score says nothing about the model.
    ``auto`` counts (a string, :func:`vbgs.mapping.config.parse_components`) pass: the
    data choose them, and their ceiling is only a ceiling."""
    if isinstance(components, int) and components >= points:
        raise ValueError(
            f"--components {components} is not fewer than the {points} pixels to fit "
            f"({what}): each pixel could get its own component, so the score would mean "
            f"nothing; {fix}"
        )


SIZE_HELP = ("frame size: one number (a synthetic scene's square side, a dataset's longer "
             "side) or WIDTHxHEIGHT, e.g. 640x480 (the field of view is horizontal)")


def size_arg(text: str):
    """``--size``: one number (a square synthetic frame, a dataset's longer side) or
    WIDTHxHEIGHT (:func:`vbgs.data.scene.parse_size`); argparse shows the reason."""
    import argparse

    from vbgs.data.scene import parse_size

    try:
        return parse_size(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


# Bytes a frame's pixel holds in memory: colour and depth (float32), and while a synthetic
# frame is ray cast its 3x3 rays per pixel and their hits (float64): a lower bound.
FRAME_BYTES_PER_PIXEL = 16
RAYCAST_BYTES_PER_PIXEL = 9 * 3 * 8 * 2


def physical_memory() -> int | None:
    """This machine's memory in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def check_fits_memory(size, frames: int, flag: str = "--size") -> None:
    """Refuse a frame size whose frames cannot fit in this machine's memory (a lower bound:
    their colour and depth, and one frame's ray cast), instead of failing inside an
    allocation with a traceback."""
    from vbgs.data.scene import size_pixels, size_text

    pixels = size_pixels(size)
    need = pixels * (frames * FRAME_BYTES_PER_PIXEL + RAYCAST_BYTES_PER_PIXEL)
    have = physical_memory()
    if have and need > have:
        raise ValueError(f"{flag} {size_text(size)}: {frames} frame{'s' * (frames != 1)} of "
                         f"{pixels:,} pixels "
                         f"need at least {need / 2**30:,.0f} GiB, and this machine has "
                         f"{have / 2**30:,.0f} GiB; give a smaller {flag}")


def check_scene_components(components: int, frames: int, size) -> None:
    """:func:`check_fewer_components` for a stream of at most ``frames`` frames of
    ``size`` (:func:`vbgs.data.scene.parse_size`), and frames that fit in memory
    (:func:`check_fits_memory`)."""
    from vbgs.data.scene import size_pixels, size_text

    check_fits_memory(size, frames)
    text = size_text(size)
    shown = text if "x" in text else f"{text}x{text}"
    check_fewer_components(components, frames * size_pixels(size),
                           f"at most {frames} frames x {shown}",
                           "use fewer --components, a larger --size or more --frames")


def meaningless_score_warning(result: dict) -> str | None:
    """A warning line when a result's score means nothing (no component was used)."""
    if result.get("components_used") == 0:
        return ("warning: components_used is 0 (no component explains any pixel), so the "
                "PSNR/SSIM above measure the background, not a fit; check the input size "
                "and --components")
    return None


def _short(value):
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list) and len(value) > 6:
        return f"[{_short(value[0])} ... {_short(value[-1])}] ({len(value)} values)"
    return value


def print_result(command: str, result: dict, *, as_json: bool) -> None:
    """Print a readable summary, or with ``as_json`` one JSON object as the last line."""
    if as_json:
        print(dumps(result))
        return
    from tabulate import tabulate  # only for the readable summary (start-up time)

    if "rows" in result:
        print(tabulate(result["rows"], headers="keys", floatfmt=".4g", tablefmt="github"))
        for path in result.get("files", []):
            print(f"wrote {path}")
        if "best" in result:
            print("best: " + ", ".join(f"{k}={_short(v)}" for k, v in result["best"].items()))
        return
    keys = [k for k in _HEADLINE if k in result] + [k for k in result if k not in _HEADLINE]
    print(f"{command}:")
    print(tabulate([(k, _short(result[k])) for k in keys], tablefmt="plain"))


# --------------------------------------------------------------------------- strict JSON


def _plain(value):
    """numpy and jax scalars and arrays as Python numbers and lists; the rest unchanged."""
    if isinstance(value, np.generic):
        return value.item()
    if not isinstance(value, (str, bytes, dict, list, tuple)) and hasattr(value, "__array__"):
        return np.asarray(value).tolist()
    return value


def _why(key: str, value: float) -> str:
    if math.isnan(value):
        return "not a number (NaN): nothing to measure it on in this run"
    sign = "+" if value > 0 else "-"
    if value > 0 and "psnr" in key.lower():
        return "+infinity: zero error, the render equals its target exactly"
    return f"{sign}infinity: the quantity has no finite value in this run"


def _bad(value) -> bool:
    return isinstance(value, float) and not math.isfinite(value)


def sanitise(value, key: str = ""):
    """``value`` with every non-finite float ``null`` and, in a dict, a ``<key>_note``
    saying why (for a list: which entries)."""
    value = _plain(value)
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            v = _plain(v)
            if _bad(v):
                out[k], out[f"{k}_note"] = None, _why(str(k), v)
                continue
            if isinstance(v, (list, tuple)):
                bad = [i for i, x in enumerate(v) if _bad(_plain(x))]
                if bad:
                    out[f"{k}_note"] = (f"entries {', '.join(map(str, bad[:8]))} are null: "
                                        f"{_why(str(k), float(_plain(v[bad[0]])))}")
            out[k] = sanitise(v, str(k))
        return out
    if isinstance(value, (list, tuple)):
        return [None if _bad(_plain(v)) else sanitise(v, key) for v in value]
    return value


def dumps(value, **kw) -> str:
    """Strict JSON of ``value`` (:func:`sanitise` first; unknown types as ``str``)."""
    return json.dumps(sanitise(value), allow_nan=False, default=str, **kw)
