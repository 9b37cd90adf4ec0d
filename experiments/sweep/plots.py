"""Figures of a sweep: PSNR against components, PSNR against seconds, forgetting
curves, a grid of renders and, on scenes that change, each learner's PSNR over the
changed and the unchanged pixels. Each function returns ``(path, note)``: the PNG written,
or ``None`` and a note saying why there is nothing to plot."""

from __future__ import annotations

import itertools
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the backend)
from matplotlib.ticker import (  # noqa: E402
    FormatStrFormatter,
    LogLocator,
    MaxNLocator,
    NullFormatter,
)

from experiments.sweep.cells import as_picture  # noqa: E402
from vbgs.data.images import read_rgb  # noqa: E402
from vbgs.data.scene_names import SYNTHETIC  # noqa: E402

# Settings that tell lines apart (when they vary), with any dotted setting of a nested
# config (``evidence.forget_after``); the others are averaged over.
LINE_STYLE = ("method", "init", "stream", "assign", "replay", "estep", "depth", "from_frame")
MAX_RENDERS_PER_ROW, MAX_RENDER_ROWS = 10, 10
RENDER_FIGURE_WIDTH = 14.0  # inches: about 1500 px at the figures' 110 dpi


def _line_columns(df: pd.DataFrame, style: list[str]) -> list[str]:
    names = [*LINE_STYLE, *sorted(c for c in style if "." in c)]
    # a setting some cells leave unset is one more value (pandas 3's astype(str) keeps a
    # missing value missing, so nunique() alone drew a fresh map and the map it stands
    # beside, whose settings differ only in from_frame, as one line)
    return [c for c in names if c in style and c in df
            and df[c].astype(str).nunique(dropna=False) > 1]


def _plain(value):
    return int(value) if isinstance(value, float) and value.is_integer() else value


def _labels(df: pd.DataFrame, cols: list[str]) -> pd.Series:
    if not cols:
        return pd.Series("all cells", index=df.index)
    parts = [df[c].map(lambda v, c=c: "" if pd.isna(v) else f"{c}={_plain(v)}") for c in cols]
    return pd.concat(parts, axis=1).apply(lambda r: ", ".join(p for p in r if p), axis=1)


def _colours(labels: pd.Series) -> dict:
    """The same colour for the same line label in every panel."""
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return {label: cycle[i % len(cycle)] for i, label in enumerate(sorted(labels.unique()))}


def _legend(fig, axes) -> None:
    """One legend for the figure, under the panels, each label once."""
    entries = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    if entries:
        fig.legend(entries.values(), entries.keys(), loc="upper center", fontsize="small",
                   bbox_to_anchor=(0.5, 0.0), ncol=min(3, len(entries)), frameon=False)


def _panels(n: int, width: float = 5.5, height: float = 4.2):
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols, height * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    return fig, list(axes.flat)


def _save(fig, path: Path, title: str) -> Path:
    top = 1 - 0.45 / fig.get_figheight()  # 0.45 in above the panels for the title
    fig.suptitle(title, fontsize=13, y=1 - 0.1 / fig.get_figheight(), va="top")
    fig.tight_layout(rect=(0, 0, 1, top))
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_psnr_vs_components(df: pd.DataFrame, style: list[str], path: Path):
    if df.empty or "components" not in df or "psnr" not in df:
        return None, "no finished cell has components and PSNR"
    cols = _line_columns(df, style)
    # components = "auto" cells are drawn as stars at the count they chose
    auto = df["components"].map(lambda k: isinstance(k, str))
    x = df["components"].where(~auto, df.get("components_chosen"))
    df = df.assign(_label=_labels(df, cols), _auto=auto,
                   _k=pd.to_numeric(x, errors="coerce")).dropna(subset=["_k"])
    colours = _colours(df["_label"])
    panels = list(df.groupby(["task", "dataset"], sort=True))
    fig, axes = _panels(len(panels))
    for ax, ((task, dataset), part) in zip(axes, panels, strict=False):
        for label, line in part[~part["_auto"]].groupby("_label", sort=True):
            stats = line.groupby("_k")["psnr"].agg(["mean", "std", "count"])
            ax.errorbar(stats.index, stats["mean"], yerr=stats["std"].fillna(0), marker="o",
                        capsize=3, label=label, color=colours[label])
        for label, line in part[part["_auto"]].groupby("_label", sort=True):
            ax.scatter(line["_k"], line["psnr"], marker="*", s=120, color=colours[label],
                       label=f"{label} (auto: K chosen)", zorder=3)
        ax.set_xscale("log", base=2)
        ticks = sorted(part.loc[~part["_auto"], "_k"].unique())
        ax.set_xticks(ticks, [str(int(t)) for t in ticks])
        ax.set_xlabel("components (count, log scale)")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(f"{task}: {dataset}")
        ax.grid(alpha=0.3)
    _legend(fig, axes)
    return _save(fig, path, "PSNR against number of components "
                 "(mean ± std over seeds and other settings)"), ""


def plot_psnr_vs_seconds(df: pd.DataFrame, style: list[str], path: Path):
    if df.empty or "seconds" not in df or "psnr" not in df:
        return None, "no finished cell reports seconds and PSNR"
    cols = [c for c in _line_columns(df, style) if c in ("method", "stream", "replay", "estep")]
    if "components" in df and df["components"].nunique() > 1:
        cols.append("components")
    df = df.assign(_label=_labels(df, cols))
    colours = _colours(df["_label"])
    markers = dict(zip(colours, itertools.cycle("osD^v<>ph*"), strict=False))
    panels = list(df.groupby("task", sort=True))
    fig, axes = _panels(len(panels), width=6.5)
    for ax, (task, part) in zip(axes, panels, strict=False):
        cold = part["cold"].eq(True) if "cold" in part else pd.Series(False, part.index)
        for label, points in part[~cold].groupby("_label", sort=True):
            ax.scatter(points["seconds"], points["psnr"], s=28, alpha=0.75,
                       marker=markers[label], color=colours[label], label=label)
        for label, points in part[cold].groupby("_label", sort=True):
            ax.scatter(points["seconds"], points["psnr"], s=28, alpha=0.75,
                       marker=markers[label], facecolors="none", edgecolors=colours[label])
        if cold.any():
            ax.scatter([], [], marker="o", facecolors="none", edgecolors="grey",
                       label="hollow: a worker's first cell of its shape (includes compilation)")
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("wall-clock seconds per fit (s, log scale)")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(f"{task} task: each point one cell")
        ax.grid(alpha=0.3, which="both")
    _legend(fig, axes)
    return _save(fig, path, "Runtime against error"), ""


def plot_forgetting(records: list[dict], path: Path):
    rows = []
    for r in records:
        curve = (r.get("result") or {}).get("forgetting_curve") if r.get("status") == "ok" else None
        for point in curve or []:
            rows.append({**r["settings"], "frames_seen": point[0], "early_psnr": point[1]})
    if not rows:
        return None, ("skipped: no cell reports a `forgetting_curve` (the scene task's "
                      "streamed cells do)")
    df = pd.DataFrame(rows)
    cols = _line_columns(df, list(df.columns))
    df = df.assign(_label=_labels(df, cols))
    colours = _colours(df["_label"])
    panels = list(df.groupby(["task", "dataset"], sort=True))
    fig, axes = _panels(len(panels), width=6.5)
    for ax, ((task, dataset), part) in zip(axes, panels, strict=False):
        for label, line in part.groupby("_label", sort=True):
            stats = line.groupby("frames_seen")["early_psnr"].agg(["mean", "std"])
            ax.plot(stats.index, stats["mean"], marker=".", label=label, color=colours[label])
            ax.fill_between(stats.index, stats["mean"] - stats["std"].fillna(0),
                            stats["mean"] + stats["std"].fillna(0), alpha=0.2,
                            color=colours[label])
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("frames seen (count)")
        ax.set_ylabel("held-out PSNR of the early views (dB)")
        ax.set_title(f"{task}: {dataset}")
        ax.grid(alpha=0.3)
    _legend(fig, axes)
    return _save(fig, path, "Forgetting: quality of the first views as the stream goes on"), ""


def _image(path: Path) -> np.ndarray | None:
    """A saved render as float RGB ``[h, w, 3]``, or None when the cell saved none."""
    return read_rgb(path) if path.is_file() else None


def plot_renders(df: pd.DataFrame, style: list[str], out: Path, path: Path):
    """A grid a person can read, one block per task and dataset. Multi-view renders (a
    scene's test views): a ground-truth row, then one row per line style (the cell with
    the most components, lowest seed). Single images (photos): one row, the target and
    then one render per line style. At most RENDER_FIGURE_WIDTH inches wide."""
    if df.empty:
        return None, "no finished cells"
    cols = _line_columns(df, style)
    df = df.assign(_label=_labels(df, cols))
    keys = [c for c in ("components", "seed") if c in df]
    rows = []  # (title, picture, captions under its parts or None)
    for (task, dataset), part in df.groupby(["task", "dataset"], sort=True):
        picked = []
        for _, line in part.groupby("_label", sort=True):
            best = line.sort_values(keys, ascending=[False, True][:len(keys)]).iloc[0]
            render = _image(out / "renders" / f"{best['key']}.png")
            if render is not None:
                picked.append((best, render))
        if not picked:
            continue
        target = _image(out / "renders" / f"{picked[0][0]['key']}.target.png")

        def caption(row) -> str:
            size = f", k={int(row['components'])}" if "components" in row else ""
            return f"{row['psnr']:.2f} dB{size}: {row['_label']}"

        strip = picked[0][1].shape[1] > 1.5 * picked[0][1].shape[0]
        if strip:
            if target is not None:
                rows.append((f"{task}: {dataset}, ground truth", target, None))
            rows += [(caption(row), render, None) for row, render in picked[:MAX_RENDER_ROWS]]
        else:
            shown = picked[:MAX_RENDERS_PER_ROW]
            images = ([target] if target is not None else []) + [r for _, r in shown]
            captions = (["target"] if target is not None else []) + [
                caption(row).replace(": ", "\n").replace(", ", "\n") for row, _ in shown]
            rows.append((f"{task}: {dataset}", images, captions))
    if not rows:
        return None, "no cell saved a render"
    pictures = [as_picture(p, limit=len(p)) if isinstance(p, list) else p for _, p, _ in rows]
    heights = [RENDER_FIGURE_WIDTH * p.shape[0] / p.shape[1] + (1.1 if c else 0.35)
               for p, (_, _, c) in zip(pictures, rows, strict=True)]
    fig, axes = plt.subplots(len(rows), 1, figsize=(RENDER_FIGURE_WIDTH, sum(heights)),
                             gridspec_kw={"height_ratios": heights}, squeeze=False)
    for ax, picture, (title, parts, captions) in zip(axes[:, 0], pictures, rows, strict=True):
        ax.imshow(np.clip(picture, 0, 1))
        ax.set_title(title, fontsize=9, loc="left")
        ax.set_yticks([])
        for spine in ax.spines.values():
            spine.set_visible(False)
        if captions:  # one caption under the centre of each part
            widths = [p.shape[1] for p in parts]
            gap = (picture.shape[1] - sum(widths)) / max(1, len(widths) - 1)
            starts = np.cumsum([0.0] + [w + gap for w in widths[:-1]])
            ax.set_xticks(starts + np.asarray(widths) / 2, captions, fontsize=7)
            ax.tick_params(length=0)
        else:
            ax.set_xticks([])
    return _save(fig, path, "Target and renders (PSNR in dB, k = components)"), ""


# The scores of a changing world's cells (experiments.tasks.change_scores), as drawn.
CHANGE_BARS = (("psnr_unchanged", "unchanged pixels (what is still there)", "tab:blue"),
               ("psnr_changed", "changed pixels (what moved, left or arrived)", "tab:orange"))


def _learner(row: pd.Series, cols: list[str]) -> str:
    """A learner's name in words from the settings that tell the cells apart (the ones
    a changing-world study varies in words, any other as ``name=value``)."""
    parts = []
    for c in cols:
        v = row.get(c)
        if v is None or pd.isna(v):
            continue
        v = _plain(v)
        if c == "method":
            parts.append({"vbgs": "VBGS", "gradient": "gradient",
                          "vbgs-polish": "VBGS-polish"}.get(v, str(v)))
        elif c == "replay":
            parts.append(f"replay {v}" if row.get("method") != "vbgs" else "")
        elif c == "from_frame":
            parts.append(f"fresh map from frame {v}" if v else "")
        elif c == "evidence.forget_after":
            parts.append(f"forget after {v}" if v else "no forgetting")
        elif c == "evidence.recolour_sigmas":
            parts.append(f"colour {v} sigmas" if v else "no colour")
        elif c == "evidence.recolour_gate":
            parts.append("no colour gate" if not v else f"colour gate {v}")
        else:
            parts.append(f"{c}={v}")
    return ", ".join(p for p in parts if p) or "all cells"


def plot_changes(df: pd.DataFrame, style: list[str], path: Path):
    """One panel per scene that changed: a pair of bars per learner (the line style,
    averaged over seeds), its final map's PSNR over the test views' changed pixels and
    over the unchanged ones, the final-state PSNR over all pixels written beside them."""
    if df.empty or "psnr_changed" not in df or not df["psnr_changed"].notna().any():
        changing = ", ".join(n for n in SYNTHETIC if n.endswith("-change"))
        return None, f"skipped: no cell reports `psnr_changed` (scenes that change: {changing})"
    df = df[df["psnr_changed"].notna()]
    cols = _line_columns(df, style)
    df = df.assign(_label=df.apply(lambda row: _learner(row, cols), axis=1))
    panels = list(df.groupby(["task", "dataset"], sort=True))
    learners = max(part["_label"].nunique() for _, part in panels)
    fig, axes = _panels(len(panels), width=6.2, height=1.0 + 0.55 * learners)
    for ax, ((task, dataset), part) in zip(axes, panels, strict=False):
        names = [m for m, _, _ in CHANGE_BARS] + ["psnr"]
        stats = part.groupby("_label", sort=True)[names].mean(numeric_only=True)
        stats = stats.sort_values("psnr")
        y = np.arange(len(stats))
        for i, (name, label, colour) in enumerate(CHANGE_BARS):
            values = stats[name].to_numpy(float)
            ax.barh(y + (0.2 if i == 0 else -0.2), values, height=0.38, color=colour,
                    label=label)
            for yy, v in zip(y + (0.2 if i == 0 else -0.2), values, strict=True):
                ax.text(v + 0.2, yy, f"{v:.1f}", va="center", fontsize=7)
        ax.set_yticks(y, [f"{label}\nall pixels {p:.2f} dB"
                          for label, p in zip(stats.index, stats["psnr"], strict=True)],
                      fontsize=7)
        ax.set_xlim(0, float(np.nanmax(stats[names].to_numpy(float))) + 3)
        ax.set_xlabel("final-state PSNR (dB)")
        ax.set_title(f"{task}: {dataset}")
        ax.grid(alpha=0.3, axis="x")
    _legend(fig, axes)
    return _save(fig, path, "A world that changes: PSNR of the final map on the pixels that "
                 "changed and on the rest"), ""
