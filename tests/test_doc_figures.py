"""Every decimal figure in the README and the docs pages is found in a committed results
file: some value rounds to it. So is every whole number that reads as a measurement by
its unit: seconds, milliseconds, megabytes or gigabytes (``391 s``, ``1069 MB``) and counts
of components forgotten or merged (``6632 forgotten``); other whole numbers (``60
frames``, ``128 px``, ``20k``) are settings more often than results and are not read.
A figure that no file holds (or that was measured once and never kept) fails here; drop
it or commit the file and its command (``results/COMMANDS.md``).

Two rules, by what the page says about a figure's source:

- **Named source (strict).** A figure's source is the results files named on its own
  line; where its line names none, those named in the rest of its unit: its table row,
  its list item (the item's first line and the lines that continue it), its paragraph
  (lines up to a blank line, a heading, a table or a list item); a heading and a line of
  a code block are units of one line. A table row or a list item also takes the names
  of its lead-in, the paragraph directly above the table or the list (a table's
  caption). Where it has a source, the figure must be held by a value in *those* files,
  not in any other. A figure with a sign keeps it (``-0.15`` is not held by 0.15); one
  without is a magnitude (``loses 3.30 dB`` is held by -3.3). A name is
  ``results/PATH`` anywhere in the text (a link's target too), or a backticked path
  (``PATH`` with a ``/`` or a data file's suffix, so ``kinect`` is a word) that exists
  under ``results/`` as given (``stream_rate/sensor/``) or as the tail of one or more
  paths there (``walk640_default20.json``, ``before/``: every path it ends stands for
  it); a folder stands for the files under it, ``*`` globs and ``{a,b}`` expands. A
  name that holds no data (a picture, a path that does not exist, the hand-written
  indexes ``results/COMMANDS.md`` and ``results/UNSTAMPED.txt``) is no source.
- **Settings (loose).** A figure in code, a code span (``--opacity 0.5``) or a line of a
  code block, is a setting or a command's argument, not a quoted result: it keeps the
  loose rule below.
- **No named source (loose).** A figure whose line and unit name no results file keeps
  the loose rule: some value in some file under ``results/`` rounds to it. It catches
  figures with no file at all, not misquotations.

Since a name that resolves to nothing would leave its figures to the loose rule without a
word, every ``results/PATH`` a page names must exist (a glob must match; a placeholder such
as ``S_K.json`` is written as a glob), except as a command's argument.

The line comes first because a paragraph often names several files, one for each of its
figures: their union would vouch for a figure set beside the wrong one. The unit comes
next because a sentence wraps: a file named on the line above or below names the source
of a figure in the same sentence. A page that quotes figures from several files in one
paragraph names each file on its figures' line.
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
FIGURE = re.compile(r"(?<![\w.])-?\d+\.\d+(?![\w.])")  # signed: -0.15 is not 0.15
# a whole number measured by its unit (the docstring): the number alone is the figure
MEASURED = re.compile(r"(?<![\w.,])-?\d+(?= ?(?:s|ms|MB|GB)\b| (?:components )?(?:forgotten|merged)\b)")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE]-?\d+)?")
DATA = (".csv", ".json", ".md", ".txt", ".toml")
NOT_A_SOURCE = {"COMMANDS.md", "UNSTAMPED.txt"}  # indexes written by hand, not results
# not measurements: the paper's arXiv id, a 16-bit PNG's range in metres, Replica's depth scale
CONSTANTS = {"2410.03592", "65.5", "6553.5"}
NAMED = re.compile(r"results/[\w.*{},/-]*")
BACKTICKED = re.compile(r"`([^`\s]+)`")
CODE_SPAN = re.compile(r"`[^`]+`")


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


ITEM = re.compile(r"^\s*(?:[-*+]|\d+\.)\s")


def units(text: str) -> list[tuple[bool, list[tuple[int, str]]]]:
    """The page's lines grouped into units (see the docstring), each line with its number;
    each unit with whether it is a line of a code block."""
    out: list[tuple[bool, list[tuple[int, str]]]] = []
    current: list[tuple[int, str]] = []
    fenced = False
    for n, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        fence = stripped.startswith("```")
        alone = fenced or stripped.startswith(("#", "|"))
        if current and (not stripped or alone or fence or ITEM.match(line)):
            out.append((False, current))
            current = []
        if fence:
            fenced = not fenced
        elif alone:
            out.append((fenced, [(n, line)]))
        elif stripped:
            current.append((n, line))
    if current:
        out.append((False, current))
    return out


def held(figure: str, values, percent: bool = False) -> bool:
    """Whether some value (sorted) rounds to ``figure`` at its decimals. A signed figure
    (-0.15) needs a value of its sign; an unsigned one is a magnitude ("loses 3.30 dB" is
    held by -3.3). A percentage (``percent``) is also held by a fraction that rounds to it
    (0.022 holds 2.2%)."""
    decimals = len(figure.split(".")[1]) if "." in figure else 0
    signs = (1,) if figure.startswith("-") else (1, -1)
    for x, half in [(float(figure), 0.5 * 10.0 ** -decimals)] + (
            [(float(figure) / 100, 0.5 * 10.0 ** -(decimals + 2))] if percent else []):
        for sign in signs:
            i = bisect.bisect_left(values, sign * x - half)
            if i < len(values) and values[i] <= sign * x + half:
                return True
    return False


@pytest.fixture(scope="module")
def values() -> list[float]:
    found = set()
    for rel in results_paths():
        if rel.endswith(DATA):
            found.update(file_values(rel))
    return sorted(found)


def _kind(first: str) -> str | None:
    """A unit's kind by its first line: a table row, a list item or neither."""
    return "row" if first.lstrip().startswith("|") else "item" if ITEM.match(first) else None


def unheld(text: str, values: list[float]) -> list[tuple[int, str, tuple[str, ...]]]:
    """The figures of a page that their rule rejects: (line, figure, named files)."""
    missing = []
    caption: tuple[str, ...] = ()
    above: list[tuple[int, str]] = []
    before = None
    for code, unit in units(text):
        kind = None if code else _kind(unit[0][1])
        if kind and kind != before:
            caption = sources(" ".join(line for _, line in above))  # the lead-in's names
        around = tuple(sorted({*sources(" ".join(line for _, line in unit)),
                               *(caption if kind else ())}))
        above, before = unit, kind
        for n, line in unit:
            named = sources(line) or around
            pool = sorted({v for rel in named for v in file_values(rel)}) if named else values
            spans = [m.span() for m in CODE_SPAN.finditer(line)]
            for m in [*FIGURE.finditer(line), *MEASURED.finditer(line)]:
                # a figure in code (`--opacity 0.5`, a code block) is a setting: loose rule
                setting = code or any(a < m.start() < b for a, b in spans)
                if m.group(0) not in CONSTANTS and not held(
                        m.group(0), values if setting else pool,
                        line[m.end():].lstrip().startswith("%")):
                    missing.append((n, m.group(0), () if setting else named))
    return missing


def _where(named: tuple[str, ...]) -> str:
    if not named:
        return "in no results file"
    more = f" and {len(named) - 3} more" if len(named) > 3 else ""
    return f"not in {', '.join(named[:3])}{more}"


@pytest.mark.parametrize("page", PAGES)
def test_every_figure_is_in_its_results_file(page, values):
    missing = [f"{page}:{n}: {figure} ({_where(named)})"
               for n, figure, named in unheld((ROOT / page).read_text(), values)]
    assert not missing, "figures their results files do not hold:\n" + "\n".join(missing)


def test_the_check_fails_on_a_figure_no_file_holds(values):
    assert held("25.99", values)  # results/example/object.json's PSNR
    assert not held("12345.678", values)
    assert not unheld("The object: 25.99 dB.", values)
    assert unheld("The object: 12345.678 dB.", values)


def test_a_named_file_must_hold_the_figure_another_file_does_not_vouch(values):
    # 25.99 is the object's PSNR in results/example/object.json and in no quick-sweep table
    assert "example/object.json" in sources("(`results/example/object.json`)")
    assert not held("25.99", file_values("quick/tables.md"))
    assert not unheld("The object reaches 25.99 dB (`results/example/object.json`).", values)
    assert unheld("The object reaches 25.99 dB ([tables](results/quick/tables.md)).", values)
    assert unheld("The object reaches 25.99 dB (`quick/tables.md`).", values)  # relative name
    assert [n for n, _, _ in unheld("a\nreaches 25.99 dB (`quick/tables.md`)", values)] == [2]
    # the same figure with no file named: the loose rule, any file
    assert not unheld("The object reaches 25.99 dB.", values)
    # a name on the next line of the paragraph applies; one in the next paragraph does not
    assert unheld("The object reaches 25.99 dB\n(see `results/quick/tables.md`).", values)
    assert not unheld("The object reaches 25.99 dB.\n\nSee `results/quick/tables.md`.", values)
    assert not unheld("- The object: 25.99 dB.\n- `results/quick/tables.md`", values)
    # the line's own name comes first: the paragraph's other names do not vouch for it
    assert unheld("25.99 dB (`quick/tables.md`)\n(`results/example/object.json`)", values)
    assert not unheld("25.99 dB\n(`results/example/object.json`)", values)


def test_a_table_row_takes_its_captions_names(values):
    table = "| scene | PSNR |\n|---|---|\n| object | 25.99 dB |\n"
    assert not unheld("Caption (`results/example/object.json`):\n\n" + table, values)
    assert unheld("Caption (`results/quick/tables.md`):\n\n" + table, values)
    assert not unheld("## A heading\n\n" + table, values)  # no caption: the loose rule
    # a row's own name comes first
    assert not unheld("Caption (`results/quick/tables.md`):\n\n"
                      "| object | 25.99 dB (`results/example/object.json`) |\n", values)


def test_a_list_item_takes_its_lead_ins_names(values):
    items = "- the object: 25.99 dB\n- the room: 22.82 dB\n"
    assert not unheld("Each scene (`results/example/object.json`, `results/standing/`):\n\n"
                      + items, values)
    assert [f for _, f, _ in unheld("Each (`results/example/object.json`):\n\n" + items,
                                    values)] == ["22.82"]
    assert not unheld("Each scene:\n\n" + items, values)  # no names: the loose rule
    # an item's own names add to its lead-in's
    assert not unheld("Each (`results/example/object.json`):\n\n- the object 25.99 dB\n"
                      "  and the room 22.82 dB (`results/standing/`)", values)


def test_a_figure_keeps_its_sign(values):
    named = "(`results/example/object.json`)"
    assert not unheld(f"25.99 dB {named}", values)
    assert unheld(f"-25.99 dB {named}", values)
    assert [f for _, f, _ in unheld(f"range 0.4-25.99 {named}", values)] == ["0.4"]
    # no sign: a magnitude (results/robustness/robustness.md's change table holds -3.3)
    loss = "(`results/robustness/robustness.md`)"
    assert not unheld(f"VBGS loses 3.30 dB {loss}", values)
    assert not unheld(f"a change of -3.30 dB {loss}", values)
    assert unheld(f"a change of -26.81 dB {loss}", values)  # 26.81 is there, -26.81 not


def test_a_setting_in_code_is_not_held_to_the_named_file(values):
    named = "(`results/example/object.json`)"
    assert not unheld(f"`--opacity 0.75` is the old rule {named}", values)
    assert unheld(f"--opacity 0.75 is the old rule {named}", values)
    assert not unheld("```bash\nrun --out results/example/object.json --opacity 0.75\n```", values)


def test_a_whole_number_with_a_unit_of_measure_is_a_figure(values):
    # results/stream_rate/sensor/room640_kinect_default20.json: "peak_memory_mb": 1068.78...
    named = "(`results/stream_rate/sensor/room640_kinect_default20.json`)"
    assert [f for _, f, _ in unheld(f"peak memory 1234 MB {named}", values)] == ["1234"]
    assert [f for _, f, _ in unheld(f"it forgets 1234 components {named}", values)] == []
    assert [f for _, f, _ in unheld(f"1234 forgotten, 77 s {named}", values)] == ["1234", "77"]
    assert not unheld(f"60 frames at 128 px, 20k components {named}", values)  # settings


def test_a_percentage_is_held_by_its_fraction(values):
    # results/splat_scale/default_walk_50000.json: "uncovered": 0.02325...
    assert not unheld("2.3% uncovered (`results/splat_scale/default_walk_50000.json`)", values)
    assert unheld("2.3 uncovered (`results/splat_scale/default_walk_50000.json`)", values)
    assert unheld("2.5% uncovered (`results/splat_scale/default_walk_50000.json`)", values)


# A page's own ``results/`` that is not ours: Replica's layout (docs/datasets.md)
LAYOUT = {"results/frame*.jpg", "results/depth*.png"}


def dangling(text: str) -> list[tuple[int, str]]:
    """The ``results/PATH`` names of a page that are no file or folder there (a glob
    matches none): (first line of the unit, name). A misspelt or placeholder name
    (``S_K.json``) would leave its figures to the loose rule without a word. Names in a
    command (a code span with a space, a code block) are arguments (``--out
    results/NAME``), and Replica's own ``results/`` layout is not ours."""
    out = []
    for code, unit in units(text):
        joined = "\n".join(line for _, line in unit)  # a code span may wrap
        commands = [m.span() for m in CODE_SPAN.finditer(joined) if " " in m.group(0).strip()]
        for m in NAMED.finditer(joined):
            name = m.group(0).rstrip(".,;:)")
            if code or name in LAYOUT or name == "results/" or any(
                    a < m.start() < b for a, b in commands):
                continue
            wanted = [x.rstrip("/") for x in _expand(name[len("results/"):])]
            if not any(fnmatch.fnmatchcase(rel.rstrip("/"), w)
                       for w in wanted for rel in results_paths()):
                out.append((unit[0][0], name))
    return out


@pytest.mark.parametrize("page", PAGES)
def test_every_results_path_a_page_names_exists(page):
    missing = [f"{page}:{n}: {name}" for n, name in dangling((ROOT / page).read_text())]
    assert not missing, "results paths that do not exist:\n" + "\n".join(missing)


def test_a_misspelt_or_placeholder_name_is_caught():
    assert dangling("25.91 dB (`results/example/objct.json`)") == [
        (1, "results/example/objct.json")]
    assert dangling("see `results/splat_scale/auto_S_K.json`")
    assert not dangling("see `results/splat_scale/auto_*_50000.json`, `results/example/`")
    assert not dangling("`tune --grid G\n--out results/tuning/prior/NAME`")  # an argument


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
