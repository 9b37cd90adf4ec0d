"""The robustness report of a sweep whose cells vary a simulated sensor's noise level and
holes apart (``experiments/configs/robustness.toml``): ``robustness.png`` and
``robustness.md``.

Two axes, read off the cells' settings:

* noise: cells without holes (``sensor_holes = "none"``), x = ``sensor_level``;
* holes: cells without noise (``sensor_level = 0``), x = the share of the training
  pixels with depth that the sensor left empty (the run's ``depth_sensor_holes``);
  random dropouts make a line, the physical holes (edges, grazing angles, range limits)
  a square of their own.

The cell with neither (level 0, no holes) is the origin of both. One line per method and
depth model the learner takes (``method``, ``sensor``), one row of panels per scene.
The table gives PSNR, its change from that origin, SSIM and depth L1 per condition.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the backend)

from vbgs.io_atomic import write_atomic, write_text_atomic  # noqa: E402
from vbgs.sensors import HOLED_SENSORS, SENSOR_HOLES, parse_holes  # noqa: E402

NO_HOLES = "none"
METHOD_NAMES = {"vbgs": "VBGS", "gradient": "gradient 3DGS", "vbgs-polish": "VBGS + polish"}
METRICS = (("psnr", "PSNR (dB)"), ("ssim", "SSIM"), ("depth_l1", "depth L1"))
MARKERS = ("o", "D", "^", "v", "P", "X")
# Marker sizes by line, largest first: lines that coincide (VBGS as exact and under a
# sensor model at level 0, which it takes as exact) still show each marker.
SIZES = (10.0, 6.5, 5.0, 4.0, 4.0, 4.0)


def study_cells(df: pd.DataFrame) -> pd.DataFrame:
    """The finished cells of a simulated sensor that makes holes, with the columns the
    report reads (``line``: the method and the depth model it learns with)."""
    need = ("simulate_sensor", "sensor_level", "sensor_holes", "psnr", "dataset", "method")
    if df.empty or any(c not in df for c in need):
        return df.iloc[0:0]
    cells = df[df["simulate_sensor"].isin(HOLED_SENSORS)].copy()
    for column in ("sensor_level", "depth_sensor_holes", "psnr", "ssim", "depth_l1"):
        if column in cells:
            cells[column] = pd.to_numeric(cells[column], errors="coerce")
    cells["sensor_holes"] = cells["sensor_holes"].fillna(SENSOR_HOLES)
    sensor = cells["sensor"].fillna("exact") if "sensor" in cells else "exact"
    cells["line"] = [line_name(m, s) for m, s in zip(
        cells["method"], np.broadcast_to(sensor, len(cells)), strict=True)]
    return cells


def line_name(method: str, sensor: str) -> str:
    """A line's name: the method and how it takes the depth (``--sensor``)."""
    how = "depth taken as exact" if sensor == "exact" else f"{sensor} measurement model"
    return f"{METHOD_NAMES.get(method, method)}, {how}"


def _noise(cells: pd.DataFrame) -> pd.DataFrame:
    return cells[cells["sensor_holes"] == NO_HOLES]


def _holes(cells: pd.DataFrame) -> pd.DataFrame:
    """Cells without noise whose holes are named (the sensor's own at level 0 are its
    physical ones, already a point of their own when asked for by name)."""
    part = cells[(cells["sensor_level"] == 0) & (cells["sensor_holes"] != SENSOR_HOLES)]
    return part.assign(physical=[parse_holes(s).physical for s in part["sensor_holes"]])


def condition(level: float, holes: str) -> str:
    """A column name: ``noise 0.5``, ``random 5 %``, ``physical``, or both parts."""
    spec = parse_holes(holes)
    if spec.own:
        hole = "own holes"
    elif spec.dropout:
        hole = ("physical + " if spec.physical else "") + f"random {100 * spec.dropout:g} %"
    else:
        hole = "physical" if spec.physical else ""
    noise = f"noise {level:g}"
    if not hole:
        return noise
    return hole if level == 0 else f"{noise}, {hole}"


def _order(level: float, holes: str) -> tuple:
    spec = parse_holes(holes)
    if holes == NO_HOLES:
        return (0, level, 0, 0.0)
    if level == 0:
        return (1, 0.0, spec.physical, spec.dropout or 0.0)
    return (2, level, not spec.own, spec.dropout or 0.0)


def _share(part: pd.DataFrame) -> float:
    """The mean share (%) of training depth left empty over a condition's cells."""
    values = part["depth_sensor_holes"] if "depth_sensor_holes" in part else pd.Series([])
    return 100.0 * float(values.mean()) if values.notna().any() else float("nan")


def plot_robustness(df: pd.DataFrame, path: Path):
    """PSNR against the noise level and against the share of depth missing; ``(path,
    note)`` as the sweep's other figures."""
    cells = study_cells(df)
    noise = _noise(cells) if len(cells) else cells
    holes = _holes(cells) if len(cells) else cells
    if (cells.empty or noise["sensor_level"].nunique() < 2
            and holes["sensor_holes"].nunique() < 2):
        return None, ("skipped: no cells vary a simulated sensor's noise level (without "
                      "holes) or its holes (at level 0); see experiments/configs/robustness.toml")
    scenes = sorted(cells["dataset"].unique())
    lines = sorted(cells["line"].unique())
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    style = {line: (colours[i % len(colours)], MARKERS[i % len(MARKERS)],
                    SIZES[min(i, len(SIZES) - 1)]) for i, line in enumerate(lines)}
    fig, axes = plt.subplots(len(scenes), 2, figsize=(11.0, 3.9 * len(scenes)),
                             squeeze=False, sharey="row")
    for row, scene in zip(axes, scenes, strict=True):
        _noise_panel(row[0], noise[noise["dataset"] == scene], style)
        _hole_panel(row[1], holes[holes["dataset"] == scene], style)
        row[0].set_title(f"{scene}: Kinect noise, no holes", fontsize=10)
        row[1].set_title(f"{scene}: holes, no noise", fontsize=10)
        row[0].set_ylabel("held-out PSNR (dB)")
    handles = [plt.Line2D([], [], color=c, marker=m, markersize=6, label=line)
               for line, (c, m, _) in style.items()]
    if holes["physical"].any():
        handles.append(plt.Line2D([], [], color="grey", marker="s", markerfacecolor="none",
                                  linestyle="none", label="hollow square: the Kinect's physical "
                                  "holes (depth edges, grazing angles, range)"))
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=2,
               fontsize="small", frameon=False)
    fig.suptitle("Held-out PSNR when the training depth is a simulated Kinect's: its noise "
                 "(left) and its holes (right)", fontsize=12)
    fig.tight_layout()
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png"))
    plt.close(fig)
    return Path(path), ""


def _noise_panel(ax, part: pd.DataFrame, style: dict) -> None:
    for line, points in part.groupby("line", sort=True):
        stats = points.groupby("sensor_level")["psnr"].mean()
        colour, marker, size = style[line]
        ax.plot(stats.index, stats.values, marker=marker, markersize=size, color=colour)
    levels = sorted(part["sensor_level"].unique())
    ax.set_xticks(levels, [f"{v:g}" for v in levels])
    ax.set_xlabel(r"noise level ($\times$ the Kinect's published $\sigma_z$)")
    ax.grid(alpha=0.3)


def _hole_panel(ax, part: pd.DataFrame, style: dict) -> None:
    for line, points in part.groupby("line", sort=True):
        colour, marker, size = style[line]
        by_spec = points.groupby("sensor_holes")
        share = by_spec.apply(_share)
        psnr = by_spec["psnr"].mean()
        physical = by_spec["physical"].first()
        random = share[~physical].sort_values()
        ax.plot(random.values, psnr[random.index].values, marker=marker, markersize=size,
                color=colour)
        if physical.any():
            ax.plot(share[physical].values, psnr[physical].values, marker="s",
                    markersize=size + 2, linestyle="none", markerfacecolor="none", color=colour)
    if part["physical"].any():
        x = part.loc[part["physical"], "depth_sensor_holes"].mean() * 100
        ax.annotate("physical\nholes", (x, part.loc[part["physical"], "psnr"].max()),
                    textcoords="offset points", xytext=(0, 10), ha="center", fontsize=8)
    ax.set_xlabel("training depth missing (% of the pixels with depth)")
    ax.grid(alpha=0.3)


def robustness_table(df: pd.DataFrame) -> str | None:
    """Markdown: per scene and method, PSNR, its change from the cell without noise or
    holes, SSIM and depth L1 at each condition, and the share of depth missing; None when
    no cell varies a simulated sensor's noise or holes."""
    cells = study_cells(df)
    if cells.empty:
        return None
    conditions = sorted({(lv, h) for lv, h in zip(cells["sensor_level"], cells["sensor_holes"],
                                                  strict=True)}, key=lambda c: _order(*c))
    names = [condition(*c) for c in conditions]
    groups = cells.groupby(["dataset", "line", "sensor_level", "sensor_holes"])
    means = groups[[m for m, _ in METRICS if m in cells]].mean()
    sections = []
    for metric, label in METRICS + (("psnr_change", "PSNR change from no noise and no "
                                     "holes (dB)"),):
        source = "psnr" if metric == "psnr_change" else metric
        if source not in means:
            continue
        rows = []
        for (scene, line), part in means[source].groupby(level=[0, 1], sort=True):
            values = {c: part.get((scene, line, *c), np.nan) for c in conditions}
            if metric == "psnr_change":
                origin = values.get((0.0, NO_HOLES), np.nan)
                values = {c: v - origin for c, v in values.items()}
            digits = 3 if source in ("ssim", "depth_l1") else 2
            rows.append({"scene": scene, "method": line,
                         **{n: (f"{v:+.{digits}f}" if metric == "psnr_change" else
                                f"{v:.{digits}f}") if np.isfinite(v) else "—"
                            for n, v in zip(names, values.values(), strict=True)}})
        sections += [f"### {label}", "", pd.DataFrame(rows).to_markdown(index=False), ""]
    shares = []
    for scene, part in cells.groupby("dataset", sort=True):
        row = {"scene": scene}
        for name, (level, holes) in zip(names, conditions, strict=True):
            chosen = (part["sensor_level"] == level) & (part["sensor_holes"] == holes)
            row[name] = f"{_share(part[chosen]):.1f}"
        shares.append(row)
    sections += ["### Training depth missing (% of the pixels with depth)", "",
                 pd.DataFrame(shares).to_markdown(index=False), ""]
    return "\n".join(sections)


def write_robustness_table(df: pd.DataFrame, path: Path, header: list[str]) -> Path | None:
    """``robustness.md`` (``header`` lines first), or None when there is nothing to show."""
    table = robustness_table(df)
    if table is None:
        return None
    return write_text_atomic(path, "\n".join([*header, "", table]))
