"""``python -m experiments.remake``: make results files again from the commands they record.

Every results file names the command that made it and the code it ran at
(:mod:`experiments.provenance`: a JSON record's ``command`` and ``code_version``, a markdown
table's first line). This reads those records under the paths given, groups the files by
command (one run serves every file it made) and says how far each lies behind the code:
how many commits changed the code paths (``vbgs``, ``depth``, ``experiments``,
``pyproject.toml``) since the commit it names, and how many of them changed the code
itself, not only its comments and docstrings (a Python file's syntax tree without its
docstrings; any change to another file counts). With ``--run`` it makes them again, one
command after another, from a clean detached checkout of one commit (``--at``, HEAD by
default) under a staging folder, never from the working tree; with ``--copy`` each file
is copied into place as soon as its command succeeds.

How a command's files are found again:

- a JSON record whose command writes no ``--out`` is what the command printed: the last
  line of its standard output that reads as a JSON object (``fit-scene --json``);
- a command with ``--out FOLDER`` (a sweep, ``tune``, ``front``, ``bench``; not
  ``write-scene``, whose ``--out`` is the dataset it writes in the checkout) is given a
  staging folder of its own in its place (two commands whose files share a results
  folder do not overwrite each other's); every file it writes there whose counterpart
  exists under the results folder its stamped files lie in is copied (its plots and CSVs
  with its tables). A stamped file renamed when it was committed (``tune``'s
  ``walk.md`` kept as ``walk50k/merge.md``, or as ``k20000_walk.md`` beside another
  run's) is found again: the one file of its kind the command wrote in that folder, or
  the one whose name the committed name ends with after a ``_``; its siblings of the
  same stem (the CSV, the plot) follow it. A file that has no counterpart is listed, not
  copied.

Refused, saying why: a table made by ``report`` (it re-reads stored cells: make the sweep
again), a command that is not ``python -m ...``, a file with no record of its command.
Commands that write a dataset folder (``write-scene``) run first: others may read it.
Files already at the chosen commit are skipped with ``--skip-current``, so an
interrupted re-make resumes where it stopped. A log of each command (the 1-minute load
before and after, seconds, exit status) goes to ``STAGE/remake.log``: the results'
``COMMANDS.md`` rows quote the loads from it.
"""

from __future__ import annotations

import argparse
import ast
import functools
import json
import os
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from experiments.provenance import CODE_PATHS, ROOT, git, recorded

SKIPPED_NAMES = ("COMMANDS.md",)  # files of prose that record no command of their own


@dataclass(frozen=True)
class Record:
    """One results file and the command and code version it records."""

    path: Path
    command: str
    version: str


@dataclass
class Job:
    """One command and the results files it made."""

    command: str
    records: list[Record] = field(default_factory=list)

    @property
    def writes_dataset(self) -> bool:
        """Whether the command writes a dataset folder (``write-scene``: its ``--out`` is
        that folder, inside the checkout, which later commands read; its record is what
        it printed)."""
        return " write-scene " in f" {self.command} "

    @property
    def out(self) -> str | None:
        """The command's ``--out`` results folder, or None when its record is what it
        printed."""
        return None if self.writes_dataset else option(self.command, "--out")

    @property
    def results_dir(self) -> Path:
        """The results folder an ``--out`` command's files lie in (their common parent)."""
        return Path(os.path.commonpath([r.path.parent for r in self.records]))


def option(command: str, name: str) -> str | None:
    """The value of ``name`` in a command line (``--out X`` or ``--out=X``), else None."""
    words = shlex.split(command)
    for i, word in enumerate(words):
        if word == name and i + 1 < len(words):
            return words[i + 1]
        if word.startswith(name + "="):
            return word.split("=", 1)[1]
    return None


def with_option(command: str, name: str, value: str) -> str:
    """``command`` with the value of ``name`` replaced by ``value``."""
    words = shlex.split(command)
    for i, word in enumerate(words):
        if word == name:
            words[i + 1] = value
        elif word.startswith(name + "="):
            words[i] = f"{name}={value}"
    return shlex.join(words)


def read_record(path: Path) -> Record | None:
    """The command and code version a results file records, or None if it names none."""
    if path.name in SKIPPED_NAMES:
        return None
    try:
        stamp = recorded(path)
    except OSError:
        return None
    return Record(path, *stamp) if stamp else None


def collect(paths: list[Path]) -> tuple[list[Record], list[Path]]:
    """The records of every JSON and markdown file under ``paths`` and the files among
    them that record no command."""
    files = sorted(f for p in paths for f in ([p] if p.is_file() else p.rglob("*"))
                   if f.suffix in (".json", ".md") and f.name not in SKIPPED_NAMES)
    records, unstamped = [], []
    for f in files:
        record = read_record(f)
        (records.append(record) if record else unstamped.append(f))
    return records, unstamped


def jobs_of(records: list[Record]) -> list[Job]:
    """The records grouped by command, ``write-scene`` first, else in path order."""
    jobs: dict[str, Job] = {}
    for r in records:
        jobs.setdefault(r.command, Job(r.command)).records.append(r)
    return sorted(jobs.values(), key=lambda j: not j.writes_dataset)


def refusal(job: Job) -> str | None:
    """Why a job cannot be made again, or None."""
    words = shlex.split(job.command)
    if len(words) < 3 or words[:2] != ["python", "-m"]:
        return "not a 'python -m' command"
    if words[2:4] == ["experiments.run", "report"]:
        return "made by 'report' from stored cells: make the sweep again"
    return None


@functools.cache  # one git call per version, however many files name it
def _commits_behind(version: str, commit: str) -> tuple[str, ...] | None:
    """The commits that changed the code paths between ``version`` and ``commit`` (None:
    the version is not a commit of this repository)."""
    base = version.removesuffix("+dirty")
    try:
        return tuple(git("rev-list", f"{base}..{commit}", "--", *CODE_PATHS).split())
    except subprocess.SubprocessError:
        return None


def behind(version: str, commit: str = "HEAD") -> int | None:
    """How many commits changed the code paths between ``version`` and ``commit`` (None:
    the version is not a commit of this repository)."""
    commits = _commits_behind(version, commit)
    return None if commits is None else len(commits)


def behind_in_code(version: str, commit: str = "HEAD") -> int | None:
    """Of :func:`behind`'s commits, those that changed the code itself (:func:`changes_code`;
    None: the version is not a commit of this repository)."""
    commits = _commits_behind(version, commit)
    return None if commits is None else sum(changes_code(c) for c in commits)


@functools.cache  # a commit is read once, however many versions lie before it
def changes_code(commit: str) -> bool:
    """Whether ``commit`` changed the code paths' code, not only comments and docstrings:
    each Python file it changed compared by :func:`same_code` with its first parent's
    (added and removed files, and files of other kinds, count as changes)."""
    names = git("diff", "--name-only", "--no-renames", f"{commit}^", commit, "--",
                *CODE_PATHS).split()
    for name in names:
        if not name.endswith(".py"):
            return True
        try:
            old, new = (git("show", f"{c}:{name}") for c in (f"{commit}^", commit))
        except subprocess.CalledProcessError:  # added or removed
            return True
        if not same_code(old, new):
            return True
    return False


def same_code(old: str, new: str) -> bool:
    """Whether two Python sources differ at most in comments, docstrings and layout: their
    syntax trees, docstrings left out, are equal (a source that does not parse is
    compared as text)."""
    try:
        return _bare(ast.parse(old)) == _bare(ast.parse(new))
    except SyntaxError:
        return old == new


def _bare(tree: ast.AST) -> str:
    """``tree`` dumped without the docstrings of its module, classes and functions."""
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
                and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree)


def listing(jobs: list[Job], commit: str) -> list[dict]:
    """One row per job: its command, files, the code versions they name, how far behind."""
    rows = []
    for job in jobs:
        versions = sorted({r.version for r in job.records})
        lags = [behind(v, commit) for v in versions]
        code = [behind_in_code(v, commit) for v in versions]
        rows.append({"command": job.command, "files": [str(r.path) for r in job.records],
                     "versions": versions,
                     "behind": None if None in lags else max(lags, default=0),
                     "in_code": None if None in code else max(code, default=0),
                     "refused": refusal(job)})
    return rows


def checkout(stage: Path, commit: str) -> Path:
    """A clean detached checkout of ``commit`` under ``stage`` (removed by
    :func:`remove_checkout` when the re-make ends)."""
    tree = stage / "checkout"
    if tree.exists():
        raise ValueError(f"{tree} exists (a re-make running there?): give another --stage")
    stage.mkdir(parents=True, exist_ok=True)
    git("worktree", "add", "--detach", str(tree), commit)
    return tree


def remove_checkout(tree: Path) -> None:
    """Remove a :func:`checkout` (and what its commands wrote inside it)."""
    git("worktree", "remove", "--force", str(tree))


def load() -> str:
    """The 1-minute load average (``/proc/loadavg``), '?' where there is none."""
    try:
        return Path("/proc/loadavg").read_text().split()[0]
    except OSError:
        return "?"


def last_json_line(text: str) -> str | None:
    """The last line of ``text`` that reads as a JSON object."""
    for line in reversed(text.splitlines()):
        try:
            if isinstance(json.loads(line), dict):
                return line
        except ValueError:
            continue
    return None


def run_job(job: Job, tree: Path, stage: Path, results: Path, copy: bool, log,
            number: int = 0) -> bool:
    """Run one job in ``tree``; its files go under ``stage``: a printed record's mirroring
    ``results`` under ``out/``, an ``--out`` command's in ``jobs/NNN`` (``number``), and
    into place with ``copy``. Returns whether the command succeeded."""
    command = job.command
    out = None
    if job.out is not None:
        out = stage / "jobs" / f"{number:03d}"
        shutil.rmtree(out, ignore_errors=True)
        command = with_option(command, "--out", str(out))
    words = shlex.split(command)
    env = {**os.environ, "PYTHONPATH": str(tree)}
    start, before = time.time(), load()
    name = job.records[0].path.relative_to(results)
    with open(stage / "logs" / (str(name).replace("/", "__") + ".err"), "w") as err:
        proc = subprocess.run([sys.executable, *words[1:]], cwd=tree, env=env, text=True,
                              stdout=subprocess.PIPE, stderr=err)
    seconds = time.time() - start
    made = []
    if proc.returncode == 0 and out is None:
        line = last_json_line(proc.stdout)
        for r in job.records:
            target = stage / "out" / r.path.relative_to(results)
            target.parent.mkdir(parents=True, exist_ok=True)
            if line is not None:
                target.write_text(line + "\n")
                made.append((target, r.path))
    elif proc.returncode == 0:
        made = counterparts(job, out, job.results_dir)
    ok = proc.returncode == 0 and bool(made)
    if ok and copy:
        for source, target in made:
            shutil.copyfile(source, target)
    log.write(f"{time.strftime('%H:%M:%S')}\tload {before} -> {load()}\t{seconds:.0f} s\t"
              f"rc {proc.returncode}\t{len(made)} files\t{job.command}\n")
    log.flush()
    return ok


def counterparts(job: Job, out: Path, here: Path) -> list[tuple[Path, Path]]:
    """``(staged, committed)`` for each file an ``--out`` command wrote under ``out``
    whose counterpart exists under ``here`` (the results folder its stamped files lie
    in), renamed files found again as the module docstring says; the others listed on
    stderr."""
    files = sorted(p for p in out.rglob("*") if p.is_file())
    wrote = {f.relative_to(out) for f in files}
    stems = {}  # a staged file's path without its suffix -> the committed one's
    for r in job.records:
        want = r.path.relative_to(here)
        if want in wrote:
            continue
        kind = [w for w in wrote if w.parent == want.parent and w.suffix == want.suffix]
        ends = [w for w in kind if want.name.endswith("_" + w.name)]
        found = ends if len(ends) == 1 else kind
        if len(found) == 1:
            stems[found[0].with_suffix("")] = want.with_suffix("")
    made = []
    for f in files:
        rel = f.relative_to(out)
        stem = stems.get(rel.with_suffix(""))  # renamed: never onto another run's name
        target = here / (rel if stem is None else stem.with_suffix(rel.suffix))
        if target.exists():
            made.append((f, target))
        else:
            print(f"  not in results, not copied: {f}", file=sys.stderr)
    return made


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.remake", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("paths", nargs="*", type=Path, default=[ROOT / "results"],
                   help="results files or folders (default: results/)")
    p.add_argument("--at", default="HEAD", metavar="COMMIT",
                   help="the commit to make them at (its clean checkout; default HEAD)")
    p.add_argument("--run", action="store_true", help="make them (else only list them)")
    p.add_argument("--stage", type=Path, default=None, metavar="FOLDER",
                   help="where the checkout, outputs and logs go (default: a new folder "
                        "under the system's temporary folder)")
    p.add_argument("--copy", action="store_true",
                   help="copy each file into place once its command succeeded")
    p.add_argument("--skip-current", action="store_true",
                   help="leave the files already at the chosen commit")
    p.add_argument("--results", type=Path, default=ROOT / "results",
                   help="the results folder the paths lie in (default: results/)")
    args = p.parse_args(argv)
    results = args.results.resolve()
    records, unstamped = collect([path.resolve() for path in args.paths])
    for f in unstamped:
        print(f"no command recorded, left out: {f}", file=sys.stderr)
    try:
        commit = git("rev-parse", "--short", "--verify", args.at + "^{commit}")
    except subprocess.CalledProcessError:
        print(f"error: --at {args.at}: not a commit of this repository", file=sys.stderr)
        return 2
    if args.skip_current:
        records = [r for r in records if r.version != commit]
    jobs = jobs_of(records)
    rows = listing(jobs, commit)
    if not args.run:
        for row in rows:
            lag = "?" if row["behind"] is None else row["behind"]
            code = "?" if row["in_code"] is None else row["in_code"]
            why = f"  REFUSED: {row['refused']}" if row["refused"] else ""
            print(f"{lag:>4} behind {code:>4} in code  {len(row['files']):3d} files  "
                  f"{row['command']}{why}")
        print(f"{len(rows)} commands, {sum(len(r['files']) for r in rows)} files, "
              f"{sum(1 for r in rows if r['behind'])} behind {commit}, "
              f"{sum(1 for r in rows if r['in_code'])} behind in code", file=sys.stderr)
        return 0
    from tqdm import tqdm

    stage = (args.stage or Path(os.environ.get("TMPDIR", "/tmp")) / f"remake-{commit}")
    stage = stage.resolve()
    tree = checkout(stage, commit)
    (stage / "logs").mkdir(parents=True, exist_ok=True)
    failed = []
    try:
        with open(stage / "remake.log", "a") as log:
            for number, job in enumerate(tqdm([j for j in jobs if refusal(j) is None],
                                              desc="commands", unit="cmd")):
                if not run_job(job, tree, stage, results, args.copy, log, number):
                    failed.append(job.command)
    finally:
        remove_checkout(tree)
    for job in jobs:
        if refusal(job):
            print(f"refused ({refusal(job)}): {job.command}", file=sys.stderr)
    for command in failed:
        print(f"failed (its log under {stage / 'logs'}): {command}", file=sys.stderr)
    print(f"made under {stage / 'out'} and {stage / 'jobs'}; log {stage / 'remake.log'}",
          file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
