"""Every results file names the code version and the command that made it: the writers
stamp what they write, and the committed results carry the stamp unless they are listed
in results/UNSTAMPED.txt (made before the stamp existed; the list only shrinks)."""

import json
import subprocess
from pathlib import Path

import jax
import numpy as np
import pytest

from experiments import provenance
from experiments.benchmarks.bench import write_table
from experiments.provenance import is_stamped_json, is_stamped_markdown
from experiments.sweep.cells import store_record
from experiments.studies.tune import write_tuning

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "results"
UNSTAMPED = RESULTS / "UNSTAMPED.txt"
INDEX = {"COMMANDS.md"}  # the index of commands, written by hand: not a results table
IGNORED = {"cells", "renders", "plan.json"}  # a sweep's local files (.gitignore)


def _git(root, *args):
    subprocess.run(["git", "-C", str(root), "-c", "user.name=t", "-c", "user.email=t@t",
                    *args], check=True, capture_output=True)


def test_the_code_version_is_the_commit_dirty_when_code_changed(tmp_path):
    repo, plain = tmp_path / "repo", tmp_path / "plain"
    (repo / "vbgs").mkdir(parents=True)
    plain.mkdir()
    _git(repo, "init", "-q")
    code = repo / "vbgs" / "a.py"
    code.write_text("x = 1\n")
    (repo / "notes.txt").write_text("a\n")
    _git(repo, "add", ".")
    _git(repo, "commit", "-q", "-m", "c")
    head = subprocess.run(["git", "-C", str(repo), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True, check=True).stdout.strip()
    version = provenance.code_version.__wrapped__  # uncached: the tree changes below
    assert version(repo) == head
    (repo / "notes.txt").write_text("b\n")  # not code: still clean
    assert version(repo) == head
    code.write_text("x = 2\n")
    assert version(repo) == head + "+dirty"
    assert version(plain) == "unknown"


def test_the_command_is_the_argv_as_run(monkeypatch):
    monkeypatch.setattr(provenance, "_command", None)
    provenance.record_command(["fit-scene", "--scene", "my room"])
    assert provenance.command() == "python -m experiments.run fit-scene --scene 'my room'"
    record = provenance.stamp({"psnr": 20.0})
    assert record["command"] == provenance.command() and record["psnr"] == 20.0
    assert record["code_version"] == provenance.code_version() and is_stamped_json(record)
    assert is_stamped_markdown(provenance.first_line() + "\n\n| a |\n")
    assert not is_stamped_markdown("Measured on: here\n")


def _first_line_ok(path: Path) -> None:
    line = path.read_text().split("\n", 1)[0]
    assert is_stamped_markdown(line), (path, line)
    assert provenance.code_version() in line


def test_each_writer_stamps_what_it_writes(tmp_path, monkeypatch):
    monkeypatch.setattr(provenance, "_command", None)
    provenance.record_command(["bench", "image"])
    rows = [{"a": 1, "psnr": 20.0}]
    for path in write_table(rows, tmp_path, "bench", command="python -m experiments.run bench"):
        if path.suffix == ".md":
            _first_line_ok(path)
    md = [p for p in write_tuning(rows, tmp_path, "tune", "python -m experiments.run tune",
                                  "about") if p.suffix == ".md"]
    _first_line_ok(md[0])
    store_record(tmp_path, {"key": "k1", "status": "ok", "settings": {}})
    cell = json.loads(next(tmp_path.rglob("k1.json")).read_text())
    assert is_stamped_json(cell) and cell["command"] == "python -m experiments.run bench image"
    # and the versions that move its last bits: this process's own
    assert cell["environment"] == provenance.environment()
    assert f"numpy {np.__version__}" in cell["environment"]
    assert f"jax {jax.__version__}" in cell["environment"]


def _results(suffix):
    return sorted(str(p.relative_to(RESULTS)) for p in RESULTS.rglob(f"*{suffix}")
                  if p.name not in INDEX and not IGNORED & set(p.relative_to(RESULTS).parts))


def _stamped(name: str) -> bool:
    return provenance.recorded(RESULTS / name) is not None


def _listed() -> list[str]:
    lines = UNSTAMPED.read_text().splitlines()
    return [line.strip() for line in lines if line.strip() and not line.startswith("#")]


@pytest.mark.parametrize("suffix", [".json", ".md"])
def test_committed_results_name_their_code_and_command(suffix):
    """A results file without the stamp fails unless it is listed as made before the
    stamp existed; a listed file that is stamped now fails too (take it off the list)."""
    listed = set(_listed())
    files = _results(suffix)
    unstamped = [f for f in files if not _stamped(f)]
    assert [f for f in unstamped if f not in listed] == [], (
        "results files without code_version and command (re-make them with the command "
        "that made them)")
    assert [f for f in files if f in listed and _stamped(f)] == [], (
        "stamped now: take these off results/UNSTAMPED.txt")


def test_the_unstamped_list_names_only_files_that_exist():
    assert [f for f in _listed() if not (RESULTS / f).is_file()] == []


def test_the_tracking_validation_refuses_the_reported_trajectories_and_stamps_its_table(
        tmp_path, capsys):
    from argparse import Namespace

    from experiments.tune_tracking import STREAMS, main, write_table

    with pytest.raises(SystemExit):
        main(["--seeds", "0", "1"])
    assert "seed 0 is the trajectories the tracking table reports" in capsys.readouterr().err
    assert len(STREAMS) == 9
    args = Namespace(seeds=[1], size=128, frames=60, components=20000)
    md = [p for p in write_table([{"variant": "default", "sum": 1.0}], tmp_path, args)
          if p.suffix == ".md"]
    _first_line_ok(md[0])
