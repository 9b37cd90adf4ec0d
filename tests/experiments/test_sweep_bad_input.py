"""Sweep folders: another config's cells are not orphaned silently, unreadable cell files
are counted and named. No cell is computed here: records are
stored by hand and the backend is stubbed."""

import json
from pathlib import Path

import pytest

import experiments.sweep.backends as backends
from experiments.run import main
from experiments.sweep.cells import cell_path, store_record


def _toml(path: Path, name: str) -> Path:
    path.write_text(f'name = "{name}"\n[fixed]\ntask = "image"\nsize = 16\niters = 2\n'
                    '[[grid]]\ndataset = "coffee"\ncomponents = 20\ninit = "data"\n'
                    'seed = [0, 1]\n')
    return path


def _record(key: str, seed: int, psnr: float) -> dict:
    settings = {"task": "image", "dataset": "coffee", "components": 20, "seed": seed}
    return {"key": key, "status": "ok", "settings": settings, "version": "test",
            "result": {"psnr": psnr, "ssim": 0.5, "components_used": 15, "seconds": 0.1}}


def _old_sweep(out: Path, name: str) -> list[str]:
    keys = ["a" * 16, "b" * 16]
    for seed, key in enumerate(keys):
        store_record(out, _record(key, seed, 20.0 + seed))
    (out / "plan.json").write_text(json.dumps({"name": name, "cells": [{"key": k} for k in keys]}))
    (out / "config.toml").write_text(f'name = "{name}"\n')
    return keys


@pytest.fixture
def no_cells_run(monkeypatch):
    monkeypatch.setattr(backends, "run_cells", lambda pending, *a, **k: iter(()))


# case 4 ------------------------------------------------------------------------------


def test_out_holding_another_configs_cells_is_refused(tmp_path, capsys, no_cells_run):
    out = tmp_path / "res"
    _old_sweep(out, "older")
    config = _toml(tmp_path / "new.toml", "newer")
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--no-report"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and (
        f"error: --out {out} holds 2 cells of config 'older' that config 'newer' does not plan"
        in err) and "pass --force" in err
    assert (out / "config.toml").read_text() == 'name = "older"\n'  # nothing replaced
    assert json.loads((out / "plan.json").read_text())["name"] == "older"


def test_force_runs_there_and_says_what_leaves_the_tables(tmp_path, capsys, no_cells_run):
    out = tmp_path / "res"
    _old_sweep(out, "older")
    config = _toml(tmp_path / "new.toml", "newer")
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--no-report", "--force"]) == 0
    assert ("note: 2 cells in " in capsys.readouterr().err
            and "note: 2 cells" in (out / "sweep.log").read_text())
    assert json.loads((out / "plan.json").read_text())["name"] == "newer"


def test_same_config_edited_is_not_refused(tmp_path, capsys, no_cells_run):
    out = tmp_path / "res"
    _old_sweep(out, "same")
    config = _toml(tmp_path / "same.toml", "same")
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--no-report"]) == 0
    assert "are not in this config's plan" in capsys.readouterr().err


def test_out_that_is_a_file_is_refused(tmp_path, capsys, no_cells_run):
    blocker = tmp_path / "res"
    blocker.write_text("x")
    config = _toml(tmp_path / "c.toml", "c")
    assert main(["sweep", "--config", str(config), "--out", str(blocker)]) == 2
    assert f"--out {blocker} is a file; give a folder" in capsys.readouterr().err


# case 6 ------------------------------------------------------------------------------


def test_report_counts_and_names_an_unreadable_cell_file(tmp_path, capsys):
    out = tmp_path / "res"
    keys = _old_sweep(out, "older")
    broken = cell_path(out, keys[1])
    broken.write_text('{"key": "bbbb", "status": "o')  # truncated
    assert main(["report", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    result = json.loads(captured.out.strip().splitlines()[-1])
    assert result["cells"] == 1 and result["unreadable"] == [str(broken)]
    assert (f"warning: 1 cell file(s) could not be read and are left out of the report: "
            f"{broken}") in captured.err
    tables = (out / "tables.md").read_text()
    assert "1 cell file(s) could not be read" in tables and str(broken) in tables
    assert "planned cells have no result yet" not in tables  # counted once, as unreadable
