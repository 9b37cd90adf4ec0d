"""Every decimal figure in the README and the docs pages is found in a committed results
file: some value rounds to it. A figure that no file holds (or that was measured once and
never kept) fails here; drop it or commit the file and its command (``results/COMMANDS.md``).

Two rules, by what the line a figure stands on says about its source:

- **Named source (strict).** When a line names results files, every figure on that line
  must be held by a value in *those* files, not in any other. A name is ``results/PATH``
  anywhere on the line (a link's target too), or a backticked path (``PATH`` with a ``/``
  or a data file's suffix, so ``kinect`` is a word) that exists under ``results/`` as given
  (``stream_rate/sensor/``) or as the tail of one or more paths there
  (``walk640_default20.json``, ``before/``: every path it ends stands for it); a
  folder stands for the files under it, ``*`` globs and ``{a,b}`` expands. A name that
  holds no data (a picture, a path that does not exist, the hand-written indexes
  ``results/COMMANDS.md`` and ``results/UNSTAMPED.txt``) is no source.
- **No named source (loose).** A line that names no results file keeps the loose rule:
  some value in some file under ``results/`` rounds to the figure. It catches figures
  with no file at all, not misquotations.

The unit is the line (a table row is one) and not the paragraph: a paragraph often names
several files, and their union would vouch for a figure the page sets beside the wrong
one. A page that states a figure names its file on the figure's own line.
"""

from __future__ import annotations

import bisect
import fnmatch
import functools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"
PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md")
                              if p.name not in ("ARCHITECTURE.md", "validation.md"))]
FIGURE = re.compile(r"(?<![\w.])\d+\.\d+(?![\w.])")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE]-?\d+)?")
DATA = (".csv", ".json", ".md", ".txt", ".toml")
NOT_A_SOURCE = {"COMMANDS.md", "UNSTAMPED.txt"}  # indexes written by hand, not results
# not measurements: the paper's arXiv id, a 16-bit PNG's range in metres, Replica's depth scale
CONSTANTS = {"2410.03592", "65.5", "6553.5"}
NAMED = re.compile(r"results/[\w.*{},/-]*")
BACKTICKED = re.compile(r"`([^`\s]+)`")


def numbers(text: str) -> set[float]:
    found = set()
    for match in NUMBER.finditer(text):
        try:
            found.add(float(match.group(0)))
        except ValueError:
            continue
    return found


@functools.cache
def file_values(rel: str) -> tuple[float, ...]:
    return tuple(sorted(numbers((RESULTS / rel).read_text(errors="replace"))))


@functools.cache
def results_paths() -> tuple[str, ...]:
    """Every file and folder under results/, relative to it (folders end in '/')."""
    out = []
    for path in RESULTS.rglob("*"):
        rel = str(path.relative_to(RESULTS))
        out.append(rel + "/" if path.is_dir() else rel)
    return tuple(sorted(out))


def _expand(name: str) -> list[str]:
    braces = re.search(r"\{([^{}]*)\}", name)
    if not braces:
        return [name]
    return [x for part in braces.group(1).split(",")
            for x in _expand(name[:braces.start()] + part + name[braces.end():])]


@functools.cache
def resolve(name: str, backticked: bool) -> tuple[str, ...]:
    """The data files under results/ that a name on a page stands for (see the docstring)."""
    name = name.rstrip(".,;:)")
    if name.startswith("results/"):
        tails = False
        name = name[len("results/"):]
    elif backticked and ("/" in name or name.endswith(DATA)):  # `kinect` is a word, not a name
        tails = True
    else:
        return ()
    paths = results_paths()
    hits: set[str] = set()
    for one in _expand(name):
        if not one or one in ("/", "*"):
            continue
        if one.endswith("/"):
            one = one.rstrip("/")
        for rel in paths:
            bare = rel.rstrip("/")
            if fnmatch.fnmatchcase(bare, one) or (tails and fnmatch.fnmatchcase(bare, "*/" + one)):
                hits.add(rel)
    files: set[str] = set()
    for rel in hits:
        files.update(p for p in paths if p.startswith(rel)) if rel.endswith("/") else files.add(rel)
    return tuple(sorted(f for f in files
                        if f.endswith(DATA) and f.rsplit("/", 1)[-1] not in NOT_A_SOURCE))


def sources(text: str) -> tuple[str, ...]:
    """The results files a unit of text names."""
    found: set[str] = set()
    for match in NAMED.finditer(text):
        found.update(resolve(match.group(0), False))
    for match in BACKTICKED.finditer(text):
        found.update(resolve(match.group(1), True))
    return tuple(sorted(found))


def held(figure: str, values) -> bool:
    """Whether some value (sorted) rounds to ``figure`` at its decimals."""
    half = 0.5 * 10.0 ** -len(figure.split(".")[1])
    x = float(figure)
    i = bisect.bisect_left(values, x - half)
    return i < len(values) and values[i] <= x + half


@pytest.fixture(scope="module")
def values() -> list[float]:
    found = set()
    for rel in results_paths():
        if rel.endswith(DATA):
            found.update(file_values(rel))
    return sorted(found)


def unheld(text: str, values: list[float]) -> list[tuple[int, str, tuple[str, ...]]]:
    """The figures of a page that their rule rejects: (line, figure, named files)."""
    missing = []
    for n, line in enumerate(text.splitlines(), 1):
        named = sources(line)
        pool = sorted({v for rel in named for v in file_values(rel)}) if named else values
        missing += [(n, m.group(0), named) for m in FIGURE.finditer(line)
                    if m.group(0) not in CONSTANTS and not held(m.group(0), pool)]
    return missing


@pytest.mark.parametrize("page", PAGES)
def test_every_figure_is_in_its_results_file(page, values):
    missing = [f"{page}:{n}: {figure}" + (f" (not in {', '.join(named)})" if named else
                                            " (in no results file)")
               for n, figure, named in unheld((ROOT / page).read_text(), values)]
    assert not missing, "figures their results files do not hold:\n" + "\n".join(missing)


def test_the_check_fails_on_a_figure_no_file_holds(values):
    assert held("25.91", values)  # results/example/object.json's PSNR
    assert not held("12345.678", values)
    assert not unheld("The object: 25.91 dB.", values)
    assert unheld("The object: 12345.678 dB.", values)


def test_a_named_file_must_hold_the_figure_another_file_does_not_vouch(values):
    # 25.91 is the object's PSNR in results/example/object.json and in no quick-sweep table
    assert "example/object.json" in sources("(`results/example/object.json`)")
    assert not held("25.91", file_values("quick/tables.md"))
    assert not unheld("The object reaches 25.91 dB (`results/example/object.json`).", values)
    assert unheld("The object reaches 25.91 dB ([tables](results/quick/tables.md)).", values)
    assert unheld("The object reaches 25.91 dB (`quick/tables.md`).", values)  # relative name
    assert [n for n, _, _ in unheld("a\nreaches 25.91 dB (`quick/tables.md`)", values)] == [2]
    # the same figure with no file named: the loose rule, any file
    assert not unheld("The object reaches 25.91 dB.", values)
    # the unit is the line: a name on the next line does not apply
    assert not unheld("The object reaches 25.91 dB\n(see `results/quick/tables.md`).", values)


def test_names_resolve_to_the_files_they_stand_for():
    assert sources("`results/example/object.json`") == ("example/object.json",)
    folder = sources("`stream_rate/sensor/`")
    assert folder and all(f.startswith("stream_rate/sensor/") for f in folder)
    assert "stream_rate/sensor/before/room640_kinect_default20.json" in folder
    assert sources("`walk640_default20.json`")  # a tail of a path under results/
    assert sources("`results/COMMANDS.md`") == ()  # the index of commands is no source
    assert sources("`vbgs/mapping/mapper.py`") == ()
    assert sources("`kinect`") == () and sources("`kinect/`")  # a word; a folder's tail


def test_the_readme_stays_short():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 300
