"""Cells: grid expansion, stable keys, running one cell, and storing its result.

A cell's key hashes its sorted settings and the code's version (:func:`package_version`:
the installed ``vbgs`` version and a fingerprint of the source of ``vbgs``, ``depth``
and ``experiments``), so the same settings under the same code find their earlier
result, and a cell made by other code is never resumed as if it were this code's (the
release number alone stayed 0.1.0 while the learner changed under it). Results live in
the sweep's folder as ``cells/<key>.json`` (written through a temporary file and
``os.replace``, :mod:`vbgs.io_atomic`, so a file that exists is complete) and its images as
``renders/<key>.png`` (the render) and ``renders/<key>.<name>.png`` (the target, ...).
The JSON is written last: it marks the cell finished.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.metadata
import itertools
import json
import os
import socket
import time
import traceback
from dataclasses import asdict, dataclass, is_dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from experiments.cli.output import dumps
from experiments.provenance import stamp
from experiments.sweep.config import SweepConfig
from experiments.sweep.rules import apply_rules
from vbgs.io_atomic import write_atomic, write_text_atomic


@functools.cache
def package_version() -> str:
    """``<release>+src.<hash>``: the installed release and the first 12 hex digits of a
    SHA-256 over the ``.py`` files of the packages that make a result (path and
    content, in path order). Any change to their code gives new cell keys."""
    try:
        release = importlib.metadata.version("vbgs")
    except importlib.metadata.PackageNotFoundError:
        release = "unknown"
    return f"{release}+src.{source_fingerprint()}"


def source_fingerprint(packages=("vbgs", "depth", "experiments")) -> str:
    """12 hex digits of a SHA-256 over the ``.py`` files under each package's folder."""
    digest = hashlib.sha256()
    for name in packages:
        root = Path(importlib.import_module(name).__file__).parent
        for path in sorted(root.rglob("*.py")):
            digest.update(f"{name}/{path.relative_to(root).as_posix()}\0".encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


@dataclass(frozen=True)
class Cell:
    key: str
    settings: tuple[tuple[str, Any], ...]  # sorted by name
    grid: int  # index of the [[grid]] it came from

    def as_dict(self) -> dict:
        return dict(self.settings)

    def label(self, keys=None) -> str:
        """``task dataset k=v ...`` over ``keys`` (default: every setting)."""
        s = self.as_dict()
        head = [str(s.get("task")), str(s.get("dataset"))]
        names = [k for k in (keys or sorted(s)) if k in s and k not in ("task", "dataset")]
        return " ".join(head + [f"{k}={s[k]}" for k in names])


@dataclass(frozen=True)
class Skipped:
    settings: tuple[tuple[str, Any], ...]
    grid: int
    reason: str


@dataclass(frozen=True)
class Plan:
    cells: tuple[Cell, ...]
    skipped: tuple[Skipped, ...]

    def varying(self) -> list[str]:
        """Settings that take more than one value over the cells (for short labels)."""
        values: dict[str, set] = {}
        for cell in self.cells:
            for k, v in cell.settings:
                values.setdefault(k, set()).add(repr(v))
        n = len(self.cells)
        return [k for k, v in values.items()
                if len(v) > 1 or sum(k in c.as_dict() for c in self.cells) < n]


# Settings that (usually) leave array shapes alone: cells differing only in these share
# compiled code. Used to send such cells to the same worker and to flag a worker's first
# cell of a shape as "cold" (its timing likely includes JAX compilation).
AFFINITY_FREE = ("seed", "order", "init", "dataset", "reassign")
_SHAPES_SEEN: set[tuple] = set()  # per process: shape signatures already run here


def shape_signature(settings: dict) -> tuple:
    return tuple(sorted((k, repr(v)) for k, v in settings.items() if k not in AFFINITY_FREE))


def cell_key(settings: dict, version: str | None = None) -> str:
    blob = json.dumps({"settings": settings, "version": version or package_version()},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def expand(config: SweepConfig) -> Plan:
    """Every grid's cartesian product, filtered by the validity rules, deduplicated."""
    version = package_version()
    cells: dict[str, Cell] = {}
    skipped = []
    for g, grid in enumerate(config.grids):
        axes = grid.as_dict()
        for combo in itertools.product(*axes.values()):
            raw = dict(zip(axes, combo, strict=True))
            verdict = apply_rules(raw)
            if verdict.settings is None:
                skipped.append(Skipped(tuple(sorted(raw.items())), g, verdict.reason))
                continue
            key = cell_key(verdict.settings, version)
            if key in cells:
                why = f"same cell as {key}: {verdict.reason or 'the same settings twice'}"
                skipped.append(Skipped(tuple(sorted(raw.items())), g, why))
                continue
            cells[key] = Cell(key, tuple(sorted(verdict.settings.items())), g)
    return Plan(tuple(cells.values()), tuple(skipped))


def jsonable(value):
    """Plain JSON types from numpy/jax scalars and arrays, dataclasses, paths, tuples."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if is_dataclass(value) and not isinstance(value, type):
        return jsonable(asdict(value))
    if isinstance(value, (str, bool, int, float)) or value is None:
        return value
    if isinstance(value, np.generic):
        return value.item()
    if hasattr(value, "__array__"):
        return np.asarray(value).tolist()
    return str(value)


MAX_VIEWS = 4  # views of a multi-view image (a scene's test views) kept in its PNG


def as_picture(image, limit: int = MAX_VIEWS) -> np.ndarray:
    """One image for a PNG: ``[h, w, 3]`` or ``[h, w]`` as is; a list or stack of views
    (``[n, h, w, 3]``, ``[n, h, w]``) as its first ``limit`` side by side, white gaps between."""
    if isinstance(image, (list, tuple)):
        views = [np.asarray(v, dtype=np.float32) for v in image[:limit]]
    else:
        img = np.asarray(image, dtype=np.float32)
        if img.ndim == 2 or (img.ndim == 3 and img.shape[-1] in (3, 4)):
            return img
        views = list(img[:limit])
    h = max(v.shape[0] for v in views)
    pad = [np.pad(v, [(0, h - v.shape[0])] + [(0, 0)] * (v.ndim - 1), constant_values=1.0)
           for v in views]
    gap = np.ones((h, max(1, h // 16), *views[0].shape[2:]), np.float32)
    return np.concatenate([x for v in pad for x in (v, gap)][:-1], axis=1)


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def failed_record(key: str, settings: dict, error: str, tb: str, **extra) -> dict:
    return {"key": key, "status": "failed", "settings": settings, "version": package_version(),
            "error": error, "traceback": tb, **extra}


def execute_cell(key: str, settings: dict) -> dict:
    """Run one cell where it is called (a worker); a task error becomes a failed record.

    Returns the record with the task's images (numpy, under ``"images"``) still in it;
    :func:`store_record` moves them to PNG files.
    """
    from experiments.sweep.tasks import run_task

    shape = shape_signature(settings)
    where = {"pid": os.getpid(), "host": socket.gethostname(), "started": _now(),
             "cold": shape not in _SHAPES_SEEN}
    if hasattr(os, "sched_getaffinity"):
        where["cpus"] = sorted(os.sched_getaffinity(0))
    _SHAPES_SEEN.add(shape)
    t0 = time.perf_counter()
    try:
        result = run_task(settings)
    except Exception as err:  # any task failure is recorded, never raised into the sweep
        record = failed_record(key, settings, f"{type(err).__name__}: {err}",
                               traceback.format_exc(), **where)
    else:
        images = result.pop("images", None) or {}
        record = {"key": key, "status": "ok", "settings": settings,
                  "version": package_version(), **where, "result": jsonable(result),
                  "images": {k: as_picture(v) for k, v in images.items()}}
    record["finished"] = _now()
    record["wall_seconds"] = time.perf_counter() - t0
    return record


def cell_path(out: Path, key: str) -> Path:
    return Path(out) / "cells" / f"{key}.json"


def stored_keys(out: Path) -> set[str]:
    """Keys of the cell files in ``out/cells``: a cell in flight is written under a hidden
    temporary name first (:mod:`vbgs.io_atomic`, names starting with a dot), which a glob
    matches too, so those are left out."""
    return {p.stem for p in (Path(out) / "cells").glob("*.json") if not p.name.startswith(".")}


def render_path(out: Path, key: str, name: str = "render") -> Path:
    suffix = "" if name == "render" else f".{name}"
    return Path(out) / "renders" / f"{key}{suffix}.png"


def _write_png(path: Path, image: np.ndarray) -> None:
    from matplotlib.image import imsave

    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 3:
        write_atomic(path, lambda tmp: imsave(tmp, np.clip(img, 0, 1), format="png"))
    else:  # a depth map or error image: colour-mapped over its own range
        write_atomic(path, lambda tmp: imsave(tmp, img, format="png", cmap="viridis"))


def store_record(out: Path, record: dict) -> dict:
    """Write the record's images, then its JSON (atomically); returns it without images."""
    record = dict(record)
    images = record.pop("images", None) or {}
    renders = {}
    for name, image in images.items():
        path = render_path(out, record["key"], name)
        _write_png(path, image)
        renders[name] = str(path.relative_to(out))
    if renders:
        record["renders"] = renders
    text = dumps(jsonable(stamp(record)), indent=1)
    write_text_atomic(cell_path(out, record["key"]), text)
    return record


def load_record(out: Path, key: str) -> dict | None:
    path = cell_path(out, key)
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def is_done(out: Path, key: str) -> bool:
    """A cell is done when it has a stored result with status ok (failed cells rerun)."""
    record = load_record(out, key)
    return record is not None and record.get("status") == "ok"
