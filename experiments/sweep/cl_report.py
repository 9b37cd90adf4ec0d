"""The continual-learning matrices of a sweep's cells (:mod:`experiments.tasks.continual`):
``cl_matrix.csv`` (one row per cell, row i and column j of its matrix) and a heat-map,
one panel per learner (the cells' line style, averaged over seeds), one row of panels
per task and dataset. Cells without a matrix (``cl_segments = 0``, static protocol,
the image task) are left out; with none at all nothing is written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from experiments.sweep.plots import _labels, _line_columns, _save, plt
from vbgs.io_atomic import write_atomic

CL_SCORES = ("cl_avg_final_psnr", "cl_forgetting", "cl_backward_transfer")
PANEL_INCHES = 3.9  # each panel's width and height
LEAD_COLUMNS = ("key", "task", "dataset", "method", "replay", "seed")  # cl_matrix.csv, first


def _with_matrix(records: list[dict]) -> list[dict]:
    return [r for r in records if r.get("status") == "ok"
            and (r.get("result") or {}).get("cl_matrix")]


def cl_matrix_rows(records: list[dict]) -> pd.DataFrame:
    """Long form: a cell's settings, then ``after_segment`` (i), ``frames_seen`` (its
    end), ``segment`` (j), ``seen`` (j <= i) and ``psnr`` (R[i, j], dB)."""
    rows = []
    for r in _with_matrix(records):
        result = r["result"]
        for i, row in enumerate(result["cl_matrix"]):
            for j, value in enumerate(row):
                rows.append({"key": r["key"], **r["settings"], "after_segment": i,
                             "frames_seen": result["cl_segment_ends"][i], "segment": j,
                             "seen": j <= i, "psnr": value})
    frame = pd.DataFrame(rows)
    matrix = ["after_segment", "frames_seen", "segment", "seen", "psnr"]
    lead = [c for c in LEAD_COLUMNS if c in frame]
    rest = sorted(set(frame.columns) - set(lead) - set(matrix))
    return frame[lead + rest + matrix] if rows else frame


def write_cl_matrix(records: list[dict], path: Path):
    """``cl_matrix.csv``; ``(path, note)`` as the figures are, ``None`` when no cell has
    a matrix."""
    rows = cl_matrix_rows(records)
    if rows.empty:
        return None, "skipped: no cell reports a `cl_matrix` (give the scene task cl_segments)"
    write_atomic(path, lambda tmp: rows.to_csv(tmp, index=False))
    return path, ""


def _learners(records: list[dict]) -> pd.DataFrame:
    """One row per cell with a matrix: its settings, line label, matrix and scores."""
    cells = pd.DataFrame([{**r["settings"], "matrix": np.asarray(r["result"]["cl_matrix"]),
                           **{k: r["result"][k] for k in CL_SCORES}}
                          for r in _with_matrix(records)])
    cols = _line_columns(cells, list(cells.columns))
    return cells.assign(_label=_labels(cells, cols), _size=cells["matrix"].map(len))


def _draw(ax, matrix: np.ndarray, vmin: float, vmax: float) -> None:
    """The matrix as coloured cells with their dB; above the diagonal (segments not
    seen yet) faded."""
    n = len(matrix)
    seen = np.tril(np.ones((n, n), dtype=bool))
    ax.imshow(np.where(seen, matrix, np.nan), cmap="viridis", vmin=vmin, vmax=vmax)
    ax.imshow(np.where(seen, np.nan, matrix), cmap="viridis", vmin=vmin, vmax=vmax, alpha=0.35)
    middle = (vmin + vmax) / 2
    for i in range(n):
        for j in range(n):
            ax.text(j, i, f"{matrix[i, j]:.1f}", ha="center", va="center", fontsize=8,
                    color="white" if seen[i, j] and matrix[i, j] < middle else "black",
                    fontstyle="normal" if seen[i, j] else "italic")
    ax.set_xticks(range(n), [str(j + 1) for j in range(n)])
    ax.set_yticks(range(n), [str(i + 1) for i in range(n)])
    ax.set_xlabel("test views of segment j")
    ax.set_ylabel("after learning segments 1..i")


def plot_cl_matrices(records: list[dict], path: Path):
    """The heat-map of every learner's matrix (mean over seeds); ``(path, note)``."""
    if not _with_matrix(records):
        return None, "skipped: no cell reports a `cl_matrix` (give the scene task cl_segments)"
    cells = _learners(records)
    groups = list(cells.groupby(["task", "dataset", "_size"], sort=True))
    per_row = max(part["_label"].nunique() for _, part in groups)
    fig, axes = plt.subplots(len(groups), per_row, figsize=(PANEL_INCHES * per_row,
                                                             PANEL_INCHES * len(groups)),
                             squeeze=False)
    for row, ((task, dataset, _), part) in zip(axes, groups, strict=True):
        learners = list(part.groupby("_label", sort=True))
        means = [np.mean(np.stack(line["matrix"].tolist()), axis=0) for _, line in learners]
        vmin, vmax = min(m.min() for m in means), max(m.max() for m in means)
        for ax, (label, line), matrix in zip(row, learners, means, strict=False):
            _draw(ax, matrix, vmin, vmax)
            a, f, b = (line[k].mean() for k in CL_SCORES)
            ax.set_title(f"{task} {dataset}: {label}\nA {a:.2f}  F {f:.2f}  BWT {b:+.2f} dB"
                         f"  (n={len(line)})", fontsize=9)
        for ax in row[len(learners):]:
            ax.set_visible(False)
    return _save(fig, path, "PSNR (dB) of segment j's test views after segment i; faded, "
                            "italic: not seen yet; colours shared along a row\n"
                            "A = average final PSNR, F = forgetting, BWT = backward "
                            "transfer (mean over seeds, n cells)"), ""
