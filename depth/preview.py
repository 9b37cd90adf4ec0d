"""A preview PNG: a few frames (top row) over their colour-mapped depth (bottom row)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vbgs.io_atomic import write_atomic

PREVIEW_FRAMES = 4  # at most this many columns
PANEL_INCHES = 3.0
DPI = 100
COLORMAP = "turbo"
MISSING_COLOUR = "black"
LOW_PERCENTILE, HIGH_PERCENTILE = 2.0, 98.0  # colour range over valid depth of all panels


def preview_indices(n_frames: int, count: int = PREVIEW_FRAMES) -> list[int]:
    """Evenly spaced frame indices (first and last included), at most ``count``."""
    if n_frames <= 0:
        return []
    return sorted(set(np.linspace(0, n_frames - 1, min(count, n_frames)).round().astype(int)))


def save_preview(path: str | Path, frames: list[np.ndarray], depths: list[np.ndarray],
                 titles: list[str]) -> Path:
    """Save RGB frames ``[h, w, 3]`` above their depth ``[h, w]`` (0 = missing, black).

    Uses matplotlib's object API with the Agg canvas, so no global backend changes.
    """
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not frames:
        raise ValueError("no frames to preview")
    valid = np.concatenate([d[d > 0].ravel() for d in depths] + [np.zeros(0)])
    lo, hi = (np.percentile(valid, [LOW_PERCENTILE, HIGH_PERCENTILE]) if valid.size
              else (0.0, 1.0))
    hi = hi if hi > lo else lo + 1.0
    cmap = colormaps[COLORMAP].with_extremes(bad=MISSING_COLOUR)
    cols = len(frames)
    size = (PANEL_INCHES * cols + 1.0, PANEL_INCHES * 2)
    fig = Figure(figsize=size, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, cols, squeeze=False)
    image = None
    for c, (rgb, depth, title) in enumerate(zip(frames, depths, titles, strict=True)):
        axes[0, c].imshow(np.clip(rgb, 0, 1))
        axes[0, c].set_title(title, fontsize=9)
        shown = np.ma.masked_where(~(depth > 0), depth)
        image = axes[1, c].imshow(shown, cmap=cmap, vmin=lo, vmax=hi)
        for ax in axes[:, c]:
            ax.set_axis_off()
    fig.colorbar(image, ax=axes[1, :].tolist(), label="depth (m)", shrink=0.9)
    return write_atomic(path, fig.savefig)
