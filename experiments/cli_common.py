"""Printing results and errors the same way for every command."""

from __future__ import annotations

import json
import sys

from tabulate import tabulate

# Keys shown first in the human-readable summary, when present.
_HEADLINE = ("psnr", "ssim", "depth_l1", "seconds", "seconds_per_frame", "components_used",
             "peak_memory_mb")


def fail(err: Exception) -> int:
    """A user-facing error: one line on stderr, exit status 2, no traceback."""
    print(f"error: {err}", file=sys.stderr)
    return 2


def _short(value):
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list) and len(value) > 6:
        return f"[{_short(value[0])} ... {_short(value[-1])}] ({len(value)} values)"
    return value


def print_result(command: str, result: dict, *, as_json: bool) -> None:
    """Print a readable summary, or with ``as_json`` one JSON object as the last line."""
    if as_json:
        print(json.dumps(result, default=float))
        return
    if "rows" in result:
        print(tabulate(result["rows"], headers="keys", floatfmt=".4g", tablefmt="github"))
        for path in result.get("files", []):
            print(f"wrote {path}")
        return
    keys = [k for k in _HEADLINE if k in result] + [k for k in result if k not in _HEADLINE]
    print(f"{command}:")
    print(tabulate([(k, _short(result[k])) for k in keys], tablefmt="plain"))
