"""Reports of a sweep folder: ``cells.csv``, ``tables.md`` and the figures.

``cells.csv`` has one row per cell (failed ones included, with their error): every
setting, every scalar the task returned, and where and how long it ran. Lists such as
the ELBO trace or the forgetting curve stay in ``cells/<key>.json``.

``tables.md`` gives PSNR / SSIM / depth L1 (and, where cells report them, forgetting =
PSNR of the early views when seen minus at the end, seconds per frame, peak memory and
replay-buffer size, and the continual-learning metrics of cells with a matrix:
average final PSNR, forgetting and backward transfer, :mod:`experiments.tasks.continual`;
and of cells on a scene that changes, the PSNR over its changed and unchanged pixels, the
unchanged pixels' retention and the first state's PSNR, :mod:`experiments.tasks.change_scores`)
as mean ± std over seeds (n = number of seeds), one table per task,
one row per combination of the other settings. A setting a
cell does not have (``assign`` for a batch fit, say) shows as "—".
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from experiments.provenance import first_line
from experiments.sweep.cells import cell_path, load_record, stored_keys
from experiments.sweep.cl_report import plot_cl_matrices, write_cl_matrix
from experiments.sweep.plots import (
    plot_changes,
    plot_forgetting,
    plot_psnr_vs_components,
    plot_psnr_vs_seconds,
    plot_renders,
)
from experiments.sweep.robustness import plot_robustness, write_robustness_table
from experiments.sweep.rules import apply_rules
from experiments.sweep.tasks import TASKS
from vbgs.io_atomic import write_atomic, write_text_atomic

# Grouping columns in this order first; any other varying setting follows.
GROUP_ORDER = ("task", "dataset", "method", "components", "init", "stream", "order", "assign",
               "replay", "estep", "depth")
METRICS = (("psnr", "PSNR (dB)"), ("ssim", "SSIM"), ("depth_l1", "depth L1"),
           ("forgetting_db", "forgetting (dB)"), ("cl_avg_final_psnr", "CL final PSNR (dB)"),
           ("cl_forgetting", "CL forgetting (dB)"), ("cl_backward_transfer", "CL BWT (dB)"),
           ("psnr_changed", "changed px (dB)"), ("psnr_unchanged", "unchanged px (dB)"),
           ("unchanged_retention", "unchanged retention (dB)"),
           ("psnr_first_state", "first state (dB)"),
           ("seconds", "fit s"),
           ("seconds_per_frame", "s/frame"), ("peak_memory_mb", "peak MB"),
           ("replay_mb", "replay MB"), ("components_used", "used"),
           ("components_chosen", "K chosen"),
           ("ate_rmse", "ATE RMSE"), ("odometry_ate_rmse", "odometry ATE"))
NOT_GROUPED = ("seed", "depth_model")  # seeds are averaged; depth_model shows as `depth`


def load_records(out: Path) -> tuple[list[dict], dict, list[Path]]:
    """The stored records of the cells the last sweep planned (all cells without a plan),
    the plan (``{}`` when there is none), and the cell files that exist but cannot be
    read (corrupt or truncated JSON, no permission): they are left out, never silently."""
    out = Path(out)
    if not out.is_dir():
        raise FileNotFoundError(f"results folder {str(out)!r} does not exist")
    plan_file = out / "plan.json"
    try:
        plan = json.loads(plan_file.read_text()) if plan_file.is_file() else {}
    except (OSError, ValueError) as err:
        raise ValueError(f"{plan_file} cannot be read ({err}); delete it to report every "
                         f"cell in {out}/cells, or run the sweep again") from err
    if plan:
        keys = [c["key"] for c in plan["cells"]]
    else:
        keys = sorted(stored_keys(out))
    records, unreadable = [], []
    for key in keys:
        record = load_record(out, key)
        if record is not None:
            records.append(record)
        elif cell_path(out, key).exists():
            unreadable.append(cell_path(out, key))
    if not records:
        bad = f" ({len(unreadable)} cell files could not be read)" if unreadable else ""
        raise FileNotFoundError(f"no finished cells in {out}/cells{bad}; run a sweep into it first")
    return records, plan, unreadable


def unreadable_note(paths: list[Path]) -> str:
    """One line naming the cell files that could not be read (at most 3 by name)."""
    names = ", ".join(str(p) for p in paths[:3]) + (f" and {len(paths) - 3} more"
                                                    if len(paths) > 3 else "")
    return (f"{len(paths)} cell file(s) could not be read and are left out of the report: "
            f"{names}; delete them and run the sweep again to recompute those cells")


def _row(record: dict, setting_names: set[str]) -> dict:
    """Settings, then the result's scalars; a result value of a setting some other cell
    sets is left out (a batch fit's ``order``, say, does not apply to it)."""
    settings = record.get("settings", {})
    row = {"key": record["key"], "status": record.get("status"), **settings}
    if "depth_model" in settings:
        row["depth"] = "sensor" if settings["depth_model"] in (None, "sensor") else "estimated"
    task = TASKS.get(settings.get("task"))
    result = record.get("result") or {}
    if result.get("oracle_start") and "init" in row:  # a stream start that read ahead
        row["init"] = f"{row['init']} (oracle)"
    for name in sorted(setting_names - set(settings)):
        if _applies(settings, name, result.get(name)):
            row[name] = result[name]  # the task's default, shown where it applies
    for name, value in result.items():
        if name in row or name in setting_names or (task and name == task.dataset_field):
            continue
        if value is None or isinstance(value, (str, bool, int, float)):
            row[name] = value
    if isinstance(row.get("early_psnr_when_seen"), (int, float)) and isinstance(
            row.get("early_psnr_at_end"), (int, float)):
        row["forgetting_db"] = row["early_psnr_when_seen"] - row["early_psnr_at_end"]
    if isinstance(row.get("replay_bytes"), (int, float)):
        row["replay_mb"] = row["replay_bytes"] / 2**20
    row["error"] = record.get("error")
    for name in ("wall_seconds", "cold", "pid", "host", "started", "finished", "version"):
        row[name] = record.get(name)
    if record.get("cpus") is not None:
        row["cpus"] = " ".join(map(str, record["cpus"]))  # the CPUs the worker could use
    return row


def _applies(settings: dict, name: str, value) -> bool:
    """Whether a setting the cell left at its task's default applies to the cell."""
    if value is None or not isinstance(value, (str, bool, int, float)):
        return False
    try:
        verdict = apply_rules({**settings, name: value})
    except Exception:  # a task module that is gone: just do not fill it in
        return False
    return verdict.settings is not None and name in verdict.settings


def cells_frame(records: list[dict]) -> pd.DataFrame:
    names = {k for r in records for k in r.get("settings", {})}
    return pd.DataFrame([_row(r, names) for r in records])


def setting_columns(records: list[dict]) -> list[str]:
    names = {k for r in records for k in r.get("settings", {})}
    if "depth_model" in names:
        names.add("depth")
    order = [c for c in GROUP_ORDER if c in names]
    return order + sorted(names - set(order))


def _cell(value):
    if pd.isna(value):
        return "—"
    return int(value) if isinstance(value, float) and value.is_integer() else value


def _mean_std(values: pd.Series) -> str:
    values = values.dropna()
    if values.empty:
        return "—"
    mean = values.mean()
    digits = 3 if abs(mean) < 10 else 2 if abs(mean) < 100 else 1
    if len(values) < 2:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {values.std(ddof=1):.{digits}f}"


def _same_where_it_applies(df: pd.DataFrame, column: str) -> bool:
    """Whether a setting has one value in every cell it applies to: one value where set,
    and, with a ``method`` column, set in all or none of each method's cells (a cell that
    leaves a setting its method reads unset runs its default, which may differ: the
    default VBGS row beside one that sets ``evidence.recolour_gate = 0``)."""
    if df[column].dropna().astype(str).nunique() != 1:
        return False
    if "method" not in df:
        return True
    set_by = df[column].notna().groupby(df["method"])
    return bool((set_by.any() == set_by.all()).all())


def summary_table(df: pd.DataFrame, settings: list[str]) -> tuple[str, dict]:
    """Markdown table of one task's ok cells, and the settings constant across them."""
    cols = [c for c in settings if c in df and c not in NOT_GROUPED and df[c].notna().any()]
    fixed = {c: _cell(df[c].dropna().iloc[0]) for c in cols if _same_where_it_applies(df, c)}
    group = [c for c in cols if c not in fixed]
    metrics = [(m, label) for m, label in METRICS if m in df and df[m].notna().any()]
    rows = []
    grouped = df.groupby(group, dropna=False, sort=True) if group else [((), df)]
    for values, part in grouped:
        values = values if isinstance(values, tuple) else (values,)
        row = {c: _cell(v) for c, v in zip(group, values, strict=True)}
        row.update({label: _mean_std(part[m]) for m, label in metrics})
        if "fit s" in row and "cold" in part:
            warm = ~part["cold"].eq(True)
            row["fit s"] = (_mean_std(part.loc[warm, "seconds"]) if warm.any()
                            else row["fit s"] + " †")
        row["n"] = len(part)
        rows.append(row)
    return pd.DataFrame(rows).to_markdown(index=False), fixed


def write_tables(df: pd.DataFrame, records: list[dict], plan: dict, figures: dict,
                 path: Path, unreadable: list[Path] = ()) -> Path:
    settings = setting_columns(records)
    ok = df[df.status == "ok"]
    lines = [first_line(), "", f"# Sweep results: {plan.get('name', Path(path).parent.name)}", ""]
    if plan.get("description"):
        lines += [plan["description"], ""]
    lines += [f"{len(df)} cells: {len(ok)} ok, {int((df.status != 'ok').sum())} failed; "
              f"{len(plan.get('skipped', []))} grid combinations skipped. "
              f"Code version {plan.get('version', '?')}.", ""]
    if unreadable:
        lines += [f"**{unreadable_note(list(unreadable))}**", ""]
    missing = len(plan.get("cells", [])) - len(df) - len(unreadable)
    if missing > 0:
        lines += [f"**{missing} planned cells have no result yet** (interrupted, or "
                  "`--max-cells`): run the sweep again to finish them.", ""]
    if plan.get("machine"):
        lines += [f"Measured on: {plan['machine']}", ""]
    lines += ["Metrics are mean ± std over seeds (n cells per row). `fit s` is the task's "
              "own timing of fit and render, over the cells that were not the first of their "
              "array shapes in their worker (those include JAX compilation; † marks a row "
              "that has only such cells).", ""]
    for task, part in ok.groupby("task", sort=True):
        table, fixed = summary_table(part, settings)
        lines += [f"## {task} task", ""]
        if fixed:
            lines += ["Same for every row (where it applies): "
                      + ", ".join(f"{k} = {v}" for k, v in fixed.items()), ""]
        lines += [table, ""]
    failed = df[df.status != "ok"]
    if len(failed):
        lines += ["## Failed cells", "", "Tracebacks are in `cells/<key>.json`; failed cells "
                  "run again on the next sweep.", ""]
        shown = failed[["key", *[c for c in settings if c in failed]]].copy()
        shown["error"] = failed["error"].map(
            lambda e: e.strip().splitlines()[0][:120] if isinstance(e, str) and e.strip() else "")
        lines += [shown.fillna("—").to_markdown(index=False), ""]
    if plan.get("skipped"):
        reasons = pd.Series([s["reason"].split(": ", 1)[-1] if s["reason"].startswith("same")
                             else s["reason"] for s in plan["skipped"]])
        lines += ["## Skipped grid combinations", ""]
        lines += [reasons.value_counts().rename_axis("reason").reset_index()
                  .to_markdown(index=False), ""]
    lines += ["## Figures", ""]
    for name, (file, note) in figures.items():
        lines.append(f"- {name}: " + (f"![{name}]({file.name})" if file else note))
    return write_text_atomic(path, "\n".join(lines) + "\n")


def robustness_header(plan: dict) -> list[str]:
    """The lines above ``robustness.md``'s tables: what ran, where, and how to read it."""
    lines = [first_line(), "", f"# Robustness to depth noise and holes: {plan.get('name', '?')}",
             ""]
    if plan.get("description"):
        lines += [plan["description"], ""]
    if plan.get("machine"):
        lines += [f"Measured on: {plan['machine']}", ""]
    return lines + [
        "Each value is the mean over the cells of a condition (seeds); every cell is a row "
        "of cells.csv and tables.md. Columns: `noise X` is the simulated sensor's noise at "
        "level X without holes; `random R %` and `physical` (depth edges, grazing angles, "
        "range limits) are holes without noise; `own holes` are the sensor's as simulated "
        "by default. The figure is robustness.png."]


def write_report(out: Path) -> dict:
    """Write cells.csv, tables.md, the figures and (cells with a continual-learning
    matrix) cl_matrix.csv into the sweep folder ``out``."""
    out = Path(out)
    records, plan, unreadable = load_records(out)
    df = cells_frame(records)
    write_atomic(out / "cells.csv", lambda tmp: df.to_csv(tmp, index=False))
    ok = df[df.status == "ok"].copy()
    style = [c for c in setting_columns(records) if c in ok]
    for column in ("psnr", "ssim", "seconds", "components"):
        if column in ok:
            ok[column] = pd.to_numeric(ok[column], errors="coerce").astype(np.float64)
    figures = {
        "PSNR against components": plot_psnr_vs_components(ok, style,
                                                           out / "psnr_vs_components.png"),
        "PSNR against wall-clock seconds": plot_psnr_vs_seconds(ok, style,
                                                                out / "psnr_vs_seconds.png"),
        "forgetting curves": plot_forgetting(records, out / "forgetting.png"),
        "renders": plot_renders(ok, style, out, out / "renders.png"),
        "PSNR against sensor noise and holes": plot_robustness(ok, out / "robustness.png"),
        "continual-learning matrices": plot_cl_matrices(records, out / "cl_matrix.png"),
        "a world that changes": plot_changes(ok, style, out / "changing.png"),
    }
    robustness = write_robustness_table(ok, out / "robustness.md", robustness_header(plan))
    cl_csv, _ = write_cl_matrix(records, out / "cl_matrix.csv")
    tables = write_tables(df, records, plan, figures, out / "tables.md", unreadable)
    files = [out / "cells.csv", tables] + [f for f, _ in figures.values() if f]
    files += [robustness] if robustness else []
    return {"results": str(out), "cells": len(df), "ok": int((df.status == "ok").sum()),
            "failed": int((df.status != "ok").sum()), "tables": str(tables),
            "csv": str(out / "cells.csv"), "figures": [str(f) for f in files[2:]],
            "cl_matrix_csv": str(cl_csv) if cl_csv else None,
            "notes": [note for f, note in figures.values() if not f],
            "unreadable": [str(p) for p in unreadable]}
