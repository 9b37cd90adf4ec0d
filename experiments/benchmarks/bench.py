"""Benchmarks: timed after compilation, written as CSV and markdown with the machine."""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import jax
import numpy as np
import pandas as pd
from experiments.progress import progress as progress_bar
from experiments.provenance import cpu_model, first_line

from vbgs.data.images import image_to_points, load_image
from vbgs.inference import model
from vbgs.io_atomic import write_atomic, write_text_atomic
from vbgs.render.image import render_image
from vbgs.render.metrics import psnr


def machine() -> str:
    """One line describing where a figure was measured."""
    cpu = cpu_model()
    backend = jax.default_backend()
    device = "" if backend == "cpu" else f" ({jax.devices()[0].device_kind})"  # e.g. NVIDIA H100
    return (f"{cpu}, {os.cpu_count()} cores, {platform.system()}, Python "
            f"{platform.python_version()}, jax {jax.__version__} on {backend}{device}")


def _block(tree):
    return jax.block_until_ready(tree)


def bench_image(sizes, components, *, iters: int = 3, image: str = "astronaut",
                progress: bool = False) -> list[dict]:
    """Seconds per batch-CAVI iteration (after compilation) and PSNR after ``iters``
    iterations, for each image size and component count (data init, seed 0)."""
    rows = []
    cells = [(s, k) for s in sizes for k in components]
    for size, k in progress_bar(cells, desc="bench image", unit="cell", enabled=progress):
        img = load_image(image, size)
        uv, rgb = image_to_points(img)
        prior = model.init(uv, rgb, k, key=jax.random.key(0), scheme="data")
        empty = model.start(prior)
        t0 = time.perf_counter()
        state, _ = model.update(empty, uv, rgb, assign="posterior")
        _block(state)
        compile_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        for _ in range(iters):
            state, _ = model.update(empty._replace(posterior=state.posterior), uv, rgb,
                                    assign="posterior")
            _block(state)
        per_iter = (time.perf_counter() - t0) / iters
        rows.append({
            "size": size, "components": k,
            "seconds_per_iter": per_iter, "first_call_s": compile_s,
            f"psnr_after_{iters + 1}_iters": psnr(render_image(state.posterior, size, size), img),
        })
    return rows


def _is_dropped_column(name: str) -> bool:
    return name == "dropped" or name.endswith("_dropped")


def mark_dropped(frame: pd.DataFrame) -> pd.DataFrame:
    """Add ``exact`` (no splat-tile overlap dropped in that row's renders) where the rows
    have ``dropped`` / ``*_dropped`` columns: a row whose tiles overflowed their capacity
    timed or scored an inexact render."""
    cols = [c for c in frame.columns if _is_dropped_column(str(c))]
    if not cols:
        return frame
    return frame.assign(exact=(frame[cols].fillna(0) == 0).all(axis=1))


def _floatfmt(frame: pd.DataFrame) -> list[str]:
    """Integers as integers (``50000``, not ``5e+04``), other numbers with 4 digits."""
    return [",.0f" if pd.api.types.is_integer_dtype(t) else ".4g" for t in frame.dtypes]


def write_table(rows: list[dict], out_dir: str | Path, name: str, *, command: str | None = None,
                settings: dict | None = None, note: str | None = None) -> list[Path]:
    """``name.csv`` and ``name.md``: a markdown table headed by the machine line, the
    ``command`` that made it, its ``settings`` (also CSV columns) and a ``note`` on how to
    read it, when given. Rows
    that dropped splat-tile overlaps are marked (``exact`` column, see
    :func:`mark_dropped`)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frame = mark_dropped(pd.DataFrame(rows))
    csv, md = out / f"{name}.csv", out / f"{name}.md"
    table_csv = frame.assign(**(settings or {}), machine=machine())
    write_atomic(csv, lambda tmp: table_csv.to_csv(tmp, index=False))
    head = [f"Measured on: {machine()}"]
    if command:
        head.append(f"Command: `{command}`")
    if settings:
        head.append("Settings: " + ", ".join(f"{k} = {v}" for k, v in settings.items()))
    if note:
        head.append(note)
    if "exact" in frame and not frame["exact"].all():
        head.append("Rows with exact = False dropped splat-tile overlaps beyond the "
                    "rasterizer's tile capacity: their renders (and timings) are not exact.")
    table = frame.to_markdown(index=False, floatfmt=_floatfmt(frame))
    write_text_atomic(md, "\n\n".join([first_line(), *head]) + f"\n\n{table}\n")
    return [csv, md]


def _time_stream(prior, points, estep: str, repeats: int = 2) -> float:
    """Median seconds per streamed frame (prior assignment) after a warm-up pass that
    compiles every padded batch size."""
    times = []
    for rep in range(repeats + 1):
        state = model.start(prior)
        for xyz, rgb in points:
            t0 = time.perf_counter()
            state, _ = model.update(state, xyz, rgb, assign="prior", estep=estep)
            _block(state.stats.count)
            if rep:
                times.append(time.perf_counter() - t0)
    return float(sorted(times)[len(times) // 2])


def bench_estep(components, *, size: int = 128, frames: int = 60, timing_frames: int = 6,
                progress: bool = False) -> list[dict]:
    """Dense against sparse E-step on the object scene: seconds per frame (warm), the
    held-out PSNR of the full stream (data init, prior assignment) and the splat-tile
    overlaps its test renders dropped."""
    from experiments.learners.start import scene_prior
    from experiments.tasks.protocol import frame_points
    from experiments.tasks.scene_task import SceneTask, run_scene
    from vbgs.data.synthetic import object_scene

    scene = object_scene(size=size, n_train=frames, n_test=8, seed=0)
    points = [frame_points(f) for f in scene.train[:timing_frames]]
    rows = []
    for k in progress_bar(components, desc="bench estep", unit="cell", enabled=progress):
        task = SceneTask(components=k, size=size, frames=frames, init="data")
        prior = scene_prior(task, scene)  # the data start a VBGS learner maps from
        row = {"size": size, "components": k,
               "points_per_frame": int(np.mean([len(p[0]) for p in points]))}
        for estep in ("dense", "sparse"):
            row[f"{estep}_s_per_frame"] = _time_stream(prior, points, estep)
            result = run_scene(SceneTask(components=k, size=size, frames=frames, init="data",
                                         estep=estep))
            row[f"{estep}_psnr"] = result.psnr
            row[f"{estep}_dropped"] = result.dropped  # splat-tile overlaps, test renders
        row["speedup"] = row["dense_s_per_frame"] / row["sparse_s_per_frame"]
        row["psnr_gap_db"] = row["sparse_psnr"] - row["dense_psnr"]
        rows.append(row)
    return rows
