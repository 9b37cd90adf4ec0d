"""experiments.remake: results files found again from the commands they record."""

import json
import subprocess
import sys

import pytest

from experiments import remake
from experiments.provenance import ROOT

try:
    SHALLOW = remake.git("rev-parse", "--is-shallow-repository") == "true"
except (OSError, subprocess.SubprocessError):  # not a git checkout: nothing to re-make
    pytest.skip("experiments.remake needs a git checkout", allow_module_level=True)

FIT = "python -m experiments.run fit-image --image astronaut --size 16 --components 16 --iters 2 --json"


def head() -> str:
    return remake.git("rev-parse", "--short", "HEAD")


def write_json(path, command, version="0000000", **fields):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"psnr": 1.0, **fields, "code_version": version,
                                "command": command}) + "\n")


def test_options_are_read_and_replaced_in_either_spelling():
    assert remake.option("python -m x sweep --out a/b --workers 1", "--out") == "a/b"
    assert remake.option("python -m x sweep --out=a/b", "--out") == "a/b"
    assert remake.option("python -m x fit-scene --json", "--out") is None
    assert (remake.with_option("python -m x sweep --out a/b --workers 1", "--out", "/s p")
            == "python -m x sweep --out '/s p' --workers 1")
    assert remake.with_option("python -m x --out=a", "--out", "c") == "python -m x --out=c"


def test_files_are_grouped_by_command_and_the_unrecorded_listed(tmp_path):
    write_json(tmp_path / "a" / "one.json", FIT)
    write_json(tmp_path / "b" / "two.json", FIT)  # the same command: one run serves both
    write_json(tmp_path / "b" / "scene.json",
               "python -m experiments.run write-scene --scene object --out runs/x --json")
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "tables.md").write_text(
        "Made by `python -m experiments.run sweep --config c.toml --out /tmp/x/t` at code "
        "`0000000+dirty`.\n\n| a |\n")
    (tmp_path / "t" / "old.md").write_text(
        "Made by `python -m experiments.run report results/t` at code `0000000`.\n")
    (tmp_path / "t" / "notes.md").write_text("# no command here\n")
    (tmp_path / "COMMANDS.md").write_text("| files | command |\n")
    (tmp_path / "t" / "list.json").write_text("[1, 2]\n")
    records, unstamped = remake.collect([tmp_path])
    assert sorted(p.name for p in unstamped) == ["list.json", "notes.md"]
    jobs = remake.jobs_of(records)
    assert len(jobs) == 4 and " write-scene " in jobs[0].command  # datasets first
    assert jobs[0].writes_dataset and jobs[0].out is None  # its --out is the dataset
    fit = next(j for j in jobs if j.command == FIT)
    assert sorted(r.path.name for r in fit.records) == ["one.json", "two.json"]
    assert fit.out is None
    sweep = next(j for j in jobs if " sweep " in j.command)
    assert sweep.out == "/tmp/x/t" and sweep.results_dir == tmp_path / "t"
    assert sweep.records[0].version == "0000000+dirty"
    refused = {j.command.split()[3]: remake.refusal(j) for j in jobs}
    assert "make the sweep again" in refused["report"]
    assert refused["sweep"] is None and refused["fit-image"] is None
    assert "python -m" in remake.refusal(remake.Job("bash make.sh"))


def test_how_far_behind_counts_commits_that_changed_the_code():
    assert remake.behind(head()) == 0
    assert remake.behind(head() + "+dirty") == 0
    assert remake.behind("unknown") is None
    if not SHALLOW:  # a shallow clone has no history to count
        first = remake.git("rev-list", "--max-parents=0", "HEAD").splitlines()[-1]
        assert remake.behind(first) > 10


def test_the_last_json_line_is_the_record():
    text = 'frames 1/2\n{"a": 1}\nnote: a line\n{"b": 2}\nnot json\n'
    assert remake.last_json_line(text) == '{"b": 2}'
    assert remake.last_json_line("[1]\nplain\n") is None


def test_a_recorded_command_is_made_again_from_a_clean_checkout(tmp_path):
    """End to end: a stale record listed, then made again at HEAD and copied into place;
    a refused table left as it was; the checkout removed afterwards."""
    results = tmp_path / "results"
    write_json(results / "fit" / "a.json", FIT, psnr=-1.0)
    stale = "Made by `python -m experiments.run report results/t` at code `0000000`.\n"
    (results / "t.md").write_text(stale)
    cmd = [sys.executable, "-m", "experiments.remake", str(results), "--results",
           str(results)]
    listed = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert listed.returncode == 0, listed.stderr
    assert FIT in listed.stdout and "REFUSED" in listed.stdout
    stage = tmp_path / "stage"
    made = subprocess.run([*cmd, "--run", "--copy", "--stage", str(stage)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    record = json.loads((results / "fit" / "a.json").read_text())
    assert record["command"] == FIT and record["code_version"] == head()
    assert record["psnr"] > 10.0 and record["components_used"] == 16
    assert (results / "t.md").read_text() == stale
    assert "refused" in made.stderr
    log = (stage / "remake.log").read_text()
    assert "rc 0\t1 files" in log and "load" in log
    assert not (stage / "checkout").exists()
    assert str(stage / "checkout") not in remake.git("worktree", "list")
    # everything is at HEAD now: nothing left to make
    again = subprocess.run([*cmd, "--skip-current"], cwd=ROOT, capture_output=True,
                           text=True, timeout=60)
    assert FIT not in again.stdout


@pytest.mark.parametrize("bad", [["--at", "no-such-commit"]])
def test_an_unknown_commit_is_refused(tmp_path, bad):
    write_json(tmp_path / "a.json", FIT)
    out = subprocess.run([sys.executable, "-m", "experiments.remake", str(tmp_path),
                          "--results", str(tmp_path), *bad], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode != 0 and "no-such-commit" in out.stderr
    assert "Traceback" not in out.stderr


def test_renamed_tables_are_found_again_among_a_commands_files(tmp_path, capsys):
    """A tune's tables committed under other names (``walk.md`` kept as ``merge.md``,
    or with a prefix as ``k20000_object.md``) are matched to what the command wrote
    again, their CSVs with them; files with no counterpart are listed, not copied."""
    here, out = tmp_path / "results", tmp_path / "jobs" / "000"
    for name in ("merge.md", "merge.csv", "k20000_object.md", "k20000_object.csv",
                 "k20000_mean.md", "k20000_mean.csv", "mean.md", "mean.csv"):
        (here / name).parent.mkdir(parents=True, exist_ok=True)
        (here / name).write_text("old\n")
    for name in ("walk.md", "walk.csv", "walk.png"):
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("new\n")
    job = remake.Job("python -m x tune --out /tmp/a", [remake.Record(here / "merge.md", "", "")])
    made = {s.name: t.name for s, t in remake.counterparts(job, out, here)}
    assert made == {"walk.md": "merge.md", "walk.csv": "merge.csv"}
    assert "walk.png" in capsys.readouterr().err
    other = tmp_path / "jobs" / "001"
    other.mkdir()
    for name in ("object.md", "object.csv", "room.md", "mean.md", "mean.csv"):
        (other / name).write_text("new\n")
    job = remake.Job("python -m x tune --out /tmp/b", [
        remake.Record(here / "k20000_object.md", "", ""),
        remake.Record(here / "k20000_mean.md", "", "")])
    made = {s.name: t.name for s, t in remake.counterparts(job, other, here)}
    # mean.md and mean.csv of another run stay as they are
    assert made == {"object.md": "k20000_object.md", "object.csv": "k20000_object.csv",
                    "mean.md": "k20000_mean.md", "mean.csv": "k20000_mean.csv"}
    assert "room.md" in capsys.readouterr().err


def test_comments_and_docstrings_are_not_code():
    """What counts as a change of the code: not a comment, a docstring or the layout;
    a changed constant, call or name does."""
    old = 'def f(x):\n    """Twice x."""\n    return 2 * x  # doubled\nK = 3\n'
    assert remake.same_code(old, 'def f(x):\n    """Twice x, said again."""\n'
                                 '    return 2 * x\n\n\nK = 3  # the count\n')
    assert remake.same_code(old, '"""A module."""\ndef f(x):\n    return 2*x\nK = 3\n')
    assert not remake.same_code(old, old.replace("K = 3", "K = 4"))
    assert not remake.same_code(old, old.replace("2 * x", "x + x"))
    assert not remake.same_code(old, "def f(x:\n")  # does not parse: compared as text


def test_how_far_behind_in_code_counts_only_code_changes():
    assert remake.behind_in_code(head()) == 0
    assert remake.behind_in_code("unknown") is None
    if not SHALLOW:  # a shallow clone has no history to count
        start = remake.git("rev-list", "--skip=12", "-n", "1", "HEAD", "--", *remake.CODE_PATHS)
        assert 0 <= remake.behind_in_code(start) <= remake.behind(start) == 12
