"""The repository speaks of what it is, never of how it was made, and carries no stray
binaries: every tracked file is read (``git ls-files``) and checked.

- No tracked file over 1 MB outside ``results/`` (a wheel or an archive committed by
  accident).
- No reference to the project's own work steps ("stop 38", "stop38", "issue 13"), to the
  way it was made ("the helper's worktree"), or a commit hash in prose (README, docs,
  configs' notes, ``results/COMMANDS.md``, code comments and docstrings). A results file
  may record the code version it ran at as a field: data files (CSV, JSON) and the
  generated tables are not read for hashes.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_BYTES = 1_000_000
SELF = "tests/test_repo_hygiene.py"  # its docstring and examples name the patterns

WORK_STEP = re.compile(r"(?<![a-z])stop ?[0-9]+|\bissues? #?[0-9]+", re.IGNORECASE)
# "helper" as the maker (a helper's worktree, shared with one helper), not a helper function
MAKER = re.compile(r"\bhelpers?'s?(?!\w)|\b(?:one|two|three|fps|another) helpers?\b", re.IGNORECASE)
# 7-40 lower-case hex characters with at least one digit and one letter: a commit hash
COMMIT = re.compile(r"(?<![\w.+/-])(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}(?![\w-])")
PROSE = (".md", ".py", ".toml", ".sh", ".txt", ".cfg", ".yml", ".yaml")
DATA = (".csv", ".json", ".png", ".jpg", ".npz", ".npy", ".ply", ".onnx")


def tracked() -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True,
                             check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [p for p in out.decode().split("\0") if p and (ROOT / p).is_file()]


def text_files() -> list[tuple[str, str]]:
    files = []
    for path in tracked():
        if path == SELF or path.endswith(DATA) or (ROOT / path).stat().st_size > MAX_BYTES:
            continue
        try:
            files.append((path, (ROOT / path).read_text(encoding="utf-8")))
        except UnicodeDecodeError:
            continue
    return files


def offences(pattern: re.Pattern, files) -> list[str]:
    return [f"{path}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(0)!r}"
            for path, text in files for m in pattern.finditer(text)]


def _hash_checked(path: str) -> bool:
    """Prose and code, not the generated tables under results/ (their ``version`` field)."""
    if path.startswith("results/"):
        return path == "results/COMMANDS.md" or path.endswith(".sh")
    return path.endswith(PROSE) or "/" not in path or path.startswith(".ci/")


def test_no_large_files_outside_results():
    big = [f"{p} ({(ROOT / p).stat().st_size / 1e6:.1f} MB)" for p in tracked()
           if not p.startswith("results/") and (ROOT / p).stat().st_size > MAX_BYTES]
    assert not big, "tracked files over 1 MB outside results/: " + ", ".join(big)


def test_no_wheels_or_archives_tracked():
    stray = [p for p in tracked() if p.endswith((".whl", ".tar.gz", ".zip", ".egg"))]
    assert not stray, stray


def test_no_work_steps_named():
    found = offences(WORK_STEP, text_files())
    assert not found, "work steps named (say what the thing is instead):\n" + "\n".join(found)


def test_no_maker_named():
    found = offences(MAKER, text_files())
    assert not found, "how it was made named:\n" + "\n".join(found)


def test_no_commit_hashes_in_prose():
    files = [(p, t) for p, t in text_files() if _hash_checked(p)]
    found = offences(COMMIT, files)
    assert not found, "commit hashes in prose (a results file records its version):\n" + \
        "\n".join(found)


@pytest.mark.parametrize("text, pattern", [
    ("made at stop 38", WORK_STEP), ("room640_stop38.csv", WORK_STEP),
    ("see issue 13", WORK_STEP), ("the helper's worktree", MAKER),
    ("shared with one helper", MAKER), ("re-run at 8c3ccb9 on", COMMIT)])
def test_the_patterns_catch_what_they_are_for(text, pattern):
    assert pattern.search(text)


@pytest.mark.parametrize("text, pattern", [
    ("from onnx import helper", MAKER), ("The helper module tf32.py", MAKER),
    ("version 0.1.0+src.f40818a1d1cb", COMMIT), ("1.5e-4 and 0x9e3779b9", COMMIT),
    ("a 100000 component map", COMMIT), ("deadbeef", COMMIT), ("stopped after 3", WORK_STEP)])
def test_the_patterns_leave_alone_what_is_fine(text, pattern):
    assert not pattern.search(text)
