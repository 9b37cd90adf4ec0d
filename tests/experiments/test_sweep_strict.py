"""``sweep --strict`` exit status, and a Dask task error keeping its traceback."""

import json
from pathlib import Path

import pytest

from experiments.run import main
from experiments.sweep import backends
from experiments.sweep.cells import Cell


def _config(tmp_path: Path, dataset: str) -> Path:
    path = tmp_path / "c.toml"
    path.write_text('name = "strict"\n[fixed]\ntask = "image"\nsize = 16\niters = 1\n'
                    f'[[grid]]\ndataset = "{dataset}"\ncomponents = 20\ninit = "data"\n')
    return path


def _sweep(tmp_path, dataset, *extra):
    return ["sweep", "--config", str(_config(tmp_path, dataset)), "--out",
            str(tmp_path / "res"), "--backend", "serial", "--json", *extra]


def test_strict_exits_1_when_a_cell_fails_and_still_prints_the_summary(tmp_path, capsys):
    photo = tmp_path / "photo.png"
    photo.write_bytes(b"not a png")  # the injected failure
    assert main(_sweep(tmp_path, str(photo), "--no-report")) == 0  # without --strict: 0
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        main(_sweep(tmp_path, str(photo), "--no-report", "--strict"))
    assert exit_.value.code == 1
    out = capsys.readouterr()
    summary = json.loads(out.out.strip().splitlines()[-1])
    assert summary["failed"] == 1 and summary["finished"] == 0
    assert "--strict: 1 cell(s) failed" in out.err and "sweep.log" in out.err


def test_strict_exits_1_when_the_report_fails(tmp_path, capsys, monkeypatch):
    import experiments.sweep.report as report

    def broken(out):
        raise RuntimeError("plotting broke")

    monkeypatch.setattr(report, "write_report", broken)
    with pytest.raises(SystemExit) as exit_:
        main(_sweep(tmp_path, "astronaut", "--strict"))
    assert exit_.value.code == 1
    out = capsys.readouterr()
    summary = json.loads(out.out.strip().splitlines()[-1])
    assert summary["finished"] == 1 and summary["failed"] == 0
    assert summary["report_error"] == "RuntimeError: plotting broke"
    assert "the report failed" in out.err


def test_strict_sweep_that_succeeds_exits_0(tmp_path, capsys):
    assert main(_sweep(tmp_path, "astronaut", "--strict", "--no-report")) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["finished"] == 1


def _raise_on_worker():
    raise KeyError("worker-lost-123")


class _LostFuture:
    """A Dask future whose task raised on the worker: ``result()`` re-raises it."""

    def result(self):
        _raise_on_worker()

    def release(self):
        pass


class _Client:
    def submit(self, *args, **kwargs):
        return _LostFuture()

    def close(self):
        pass


def test_dask_task_error_keeps_message_and_traceback(monkeypatch):
    distributed = pytest.importorskip("dask.distributed")
    monkeypatch.setattr(distributed, "as_completed", iter)
    cell = Cell(key="abc", settings=(("size", 16), ("task", "image")), grid=0)
    [record] = list(backends.run_dask([cell], _Client()))
    assert record["status"] == "failed" and record["key"] == "abc"
    assert record["settings"] == {"size": 16, "task": "image"}
    assert record["error"] == "KeyError: 'worker-lost-123'"
    assert record["traceback"].startswith("Traceback (most recent call last)")
    assert "_raise_on_worker" in record["traceback"]


def test_a_users_sweep_writes_to_the_ignored_runs_folder(tmp_path):
    """Without --out a sweep writes runs/sweep/<name> under the working directory (git
    ignores /runs/), never the committed results/ snapshot."""
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-m", "experiments.run", "sweep", "--config",
                          "quick", "--max-cells", "1"], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert (tmp_path / "runs" / "sweep" / "quick").is_dir()
    assert not (tmp_path / "results").exists()
