"""``sweep`` and ``report`` commands of ``python -m experiments.run``.

A sweep writes into its results folder (default ``results/<config name>``):
``config.toml`` (a copy), ``plan.json`` (the cells and skipped combinations),
``sweep.log`` (one line per cell), ``cells/<key>.json``, ``renders/<key>*.png`` and,
at the end, the report (``cells.csv``, ``tables.md``, figures).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from tqdm.auto import tqdm

from experiments.progress import progress as progress_bar
from experiments.cli.output import dumps

CONFIGS = Path(__file__).resolve().parents[1] / "configs"  # the bundled configs


def _config_path(text: str) -> Path:
    """A config file path, or the name of a bundled config (``quick``, ``paper``)."""
    path = Path(text)
    bundled = CONFIGS / f"{text}.toml"
    if not path.exists() and path.suffix == "" and bundled.is_file():
        return bundled
    return path


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def add_sweep(sub) -> None:
    from experiments.sweep.backends import BACKENDS

    p = sub.add_parser("sweep", help="run a grid of cells from a TOML config (resumable), "
                       "then write tables and plots")
    p.add_argument("--config", default="quick", type=_config_path,
                   help="sweep config: a TOML file, or a bundled config's name "
                        f"({', '.join(sorted(c.stem for c in CONFIGS.glob('*.toml')))}); "
                        "default: quick")
    p.add_argument("--out", help="results folder (default: runs/sweep/<config name>, "
                   "ignored by git; committed snapshots name --out results/<config name>)")
    p.add_argument("--backend", choices=BACKENDS, default="local",
                   help="local: process pool on this machine; serial: in this process; "
                        "dask: an existing Dask cluster (--scheduler)")
    p.add_argument("--scheduler", help="Dask scheduler address for --backend dask")
    p.add_argument("--workers", type=_positive,
                   help=f"local worker processes (default: all {os.cpu_count()} cores)")
    p.add_argument("--force", action="store_true",
                   help="re-run cells that already finished; also run into an --out that "
                        "holds another config's cells")
    p.add_argument("--max-cells", type=_positive, help="run at most this many pending cells")
    p.add_argument("--no-report", action="store_true",
                   help="skip the tables and figures at the end (run `report` later)")
    p.add_argument("--strict", action="store_true",
                   help="exit with status 1 when a cell or the report failed (for scripts, CI)")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


def add_report(sub) -> None:
    p = sub.add_parser("report", help="tables and plots of a sweep's results folder")
    p.add_argument("results_dir", help="a sweep's results folder, e.g. results/ablations")
    p.add_argument("--json", action="store_true", help="last stdout line: one JSON object")


class SweepLog:
    """``sweep.log``: appended line by line, flushed at once (survives a kill)."""

    def __init__(self, path: Path):
        self.path = path

    def write(self, message: str) -> None:
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        with open(self.path, "a") as f:
            f.write(f"{stamp} | {message}\n")


def _metrics(record: dict) -> str:
    if record["status"] != "ok":
        return record.get("error", "").splitlines()[0][:160] if record.get("error") else ""
    result = record["result"]
    return " ".join(f"{k}={result[k]:.4g}" for k in ("psnr", "ssim", "depth_l1")
                    if isinstance(result.get(k), (int, float)))


def _write_plan(out: Path, config, plan, version: str) -> None:
    from experiments.benchmarks.bench import machine
    from experiments.provenance import stamp
    from vbgs.io_atomic import write_text_atomic

    doc = {"name": config.name, "description": config.description, "config": config.source,
           "version": version, "machine": machine(),
           "cells": [{"key": c.key, "grid": c.grid, "settings": c.as_dict()}
                     for c in plan.cells],
           "skipped": [{"grid": s.grid, "settings": dict(s.settings), "reason": s.reason}
                       for s in plan.skipped]}
    write_text_atomic(out / "plan.json", dumps(stamp(doc), indent=1))
    write_text_atomic(out / "config.toml", Path(config.source).read_text())


def _run(records, pending: list, labels: list[str], out: Path, log: SweepLog,
         name: str) -> dict:
    """Store and log each record as it arrives; returns the ok/failed counts."""
    from experiments.sweep.cells import store_record

    by_key = {c.key: c for c in pending}
    counts = {"ok": 0, "failed": 0}
    bar = progress_bar(total=len(pending), unit="cell", desc=f"sweep {name}",
                       enabled=bool(pending))
    try:
        for i, record in enumerate(records, 1):
            record = store_record(out, record)
            counts["ok" if record["status"] == "ok" else "failed"] += 1
            wall = record.get("wall_seconds")
            log.write(f"{record['status']:<8} | {i}/{len(pending)} | {record['key']} | "
                      f"{by_key[record['key']].label(labels)} | {_metrics(record)} | "
                      + (f"{wall:.1f} s | " if wall is not None else "")
                      + f"pid {record.get('pid', '?')}@{record.get('host', '?')}")
            if record["status"] != "ok":
                tqdm.write(f"cell {record['key']} failed: {_metrics(record)}", file=sys.stderr)
            bar.update()
            bar.set_postfix(failed=counts["failed"], refresh=False)
    except KeyboardInterrupt:
        bar.close()
        log.write(f"interrupted after {counts['ok'] + counts['failed']} cells")
        print(f"interrupted: {counts['ok'] + counts['failed']} cells stored in {out}/cells; "
              "run the same command again to finish the rest", file=sys.stderr)
        raise SystemExit(130) from None
    bar.close()
    return counts


def check_out(out: Path, config, plan, force: bool) -> list[str]:
    """Check the results folder before anything runs; return the stored cells this plan
    leaves out (the caller says so).

    Refuses a path that is a file, and (unless ``force``) a folder holding cells of a
    config with another name (or of an unknown one: no ``plan.json``) that this plan
    does not have: the new config.toml, cells.csv and tables.md would replace the old
    ones and orphan those cells without a word.
    """
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file; give a folder for the results")
    if not out.is_dir():
        return []
    from experiments.sweep.cells import stored_keys

    orphans = sorted(stored_keys(out) - {c.key for c in plan.cells})
    if not orphans:
        return []
    try:
        previous = json.loads((out / "plan.json").read_text()).get("name")
    except (OSError, ValueError, AttributeError):
        previous = None
    if previous != config.name and not force:
        which = f"config {previous!r}" if previous else "an unknown config (no plan.json)"
        raise ValueError(
            f"--out {out} holds {len(orphans)} cells of {which} that config {config.name!r} "
            f"does not plan; running here would replace its config.toml, cells.csv and "
            f"tables.md and leave them out. Use another --out, or pass --force to run here "
            f"anyway")
    return orphans


def run_sweep(args) -> dict:
    from experiments.sweep.backends import run_cells
    from experiments.sweep.cells import expand, is_done, package_version
    from experiments.sweep.config import ConfigError, load_config

    t0 = time.perf_counter()
    config = load_config(args.config)
    plan = expand(config)
    if not plan.cells:
        reasons = sorted({s.reason for s in plan.skipped})
        raise ConfigError(f"{config.source}: the grids make no cells; every combination was "
                          f"skipped: {'; '.join(reasons[:3])}")
    # a user's run goes to the ignored runs/ folder, so it never dirties the checkout; the
    # committed snapshots are written with an explicit --out results/NAME
    out = Path(args.out or Path("runs") / "sweep" / config.name)
    orphans = check_out(out, config, plan, args.force)
    workers = args.workers or os.cpu_count() or 1
    done = [] if args.force else [c for c in plan.cells if is_done(out, c.key)]
    finished = {c.key for c in done}
    todo = [c for c in plan.cells if c.key not in finished]
    pending = todo[:args.max_cells] if args.max_cells else todo
    # the backend is checked (Dask: connected) before anything is written
    records = run_cells(pending, args.backend, workers=workers, scheduler=args.scheduler)
    out.mkdir(parents=True, exist_ok=True)
    _write_plan(out, config, plan, package_version())
    log = SweepLog(out / "sweep.log")
    log.write(f"sweep {config.name} from {config.source}: {len(plan.cells)} cells, "
              f"{len(done)} already finished, {len(pending)} to run, "
              f"{len(plan.skipped)} combinations skipped; backend {args.backend}"
              + (f" ({workers} workers)" if args.backend == "local" else ""))
    for s in plan.skipped:
        log.write(f"skipped  | grid {s.grid} | {dict(s.settings)} | {s.reason}")
    if orphans:
        note = (f"note: {len(orphans)} cells in {out}/cells are not in this config's plan; "
                "they stay on disk but leave the tables")
        log.write(note)
        print(note, file=sys.stderr)
    counts = _run(records, pending, plan.varying(), out, log, config.name)
    try:
        report = ({"tables": None, "csv": None, "figures": []} if args.no_report
                  else _report(out))
    except Exception as err:  # the cells are stored; a report bug must not hide that
        log.write(f"report failed: {type(err).__name__}: {err}")
        tqdm.write(f"report failed ({type(err).__name__}: {err}); the cells are stored in "
                   f"{out}/cells; retry with: python -m experiments.run report {out}",
                   file=sys.stderr)
        report = {"tables": None, "csv": None, "figures": [],
                  "error": f"{type(err).__name__}: {err}"}
    wall = time.perf_counter() - t0
    log.write(f"done: {counts['ok']} finished, {counts['failed']} failed, {len(done)} reused, "
              f"{len(todo) - len(pending)} not run (--max-cells), {wall:.1f} s; "
              f"tables in {report['tables']}")
    summary = {
        "config": config.name, "results": str(out), "backend": args.backend,
        "cells": len(plan.cells), "finished": counts["ok"], "failed": counts["failed"],
        "reused": len(done), "skipped": len(plan.skipped),
        "not_run": len(todo) - len(pending), "wall_seconds": round(wall, 2),
        "tables": report["tables"], "csv": report["csv"], "figures": report["figures"],
        "log": str(out / "sweep.log"),
    }
    if args.backend == "local":
        summary["workers"] = min(workers, max(len(pending), 1))
    if report.get("error"):
        summary["report_error"] = report["error"]
    if report.get("unreadable"):
        summary["unreadable"] = report["unreadable"]
    if counts["failed"]:
        summary["note"] = "failed cells keep their traceback in cells/<key>.json and rerun next time"
    if getattr(args, "strict", False) and (counts["failed"] or report.get("error")):
        _strict_exit(summary, as_json=args.json)
    return summary


def _strict_exit(summary: dict, *, as_json: bool) -> None:
    """``--strict``: print the summary as usual, then exit with status 1."""
    from experiments.cli.output import print_result

    print_result("sweep", summary, as_json=as_json)
    what = [f"{summary['failed']} cell(s) failed"] if summary["failed"] else []
    what += ["the report failed"] if summary.get("report_error") else []
    print(f"error: --strict: {' and '.join(what)}; see {summary['log']}", file=sys.stderr)
    raise SystemExit(1)


def _report(out: Path) -> dict:
    """Write the report; name on stderr any cell file it had to leave out."""
    from experiments.sweep.report import unreadable_note, write_report

    report = write_report(out)
    if report.get("unreadable"):
        print(f"warning: {unreadable_note([Path(p) for p in report['unreadable']])}",
              file=sys.stderr)
    return report


def run_report(args) -> dict:
    return _report(Path(args.results_dir))
