"""Every decimal figure in the README and the docs pages is found in a committed results
file: some value in some file under ``results/`` rounds to it. A figure that no file
holds (or that was measured once and never kept) fails here; drop it or commit the file
and its command (``results/COMMANDS.md``).

The check is loose on purpose (a figure may match a value of another file), so it
catches figures with no file at all, not every misquotation: the pages name the file
beside each figure.
"""

from __future__ import annotations

import bisect
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md")
                              if p.name not in ("ARCHITECTURE.md", "validation.md"))]
FIGURE = re.compile(r"(?<![\w.])\d+\.\d+(?![\w.])")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE]-?\d+)?")
# not measurements: the paper's arXiv id, a 16-bit PNG's range in metres, Replica's depth scale
CONSTANTS = {"2410.03592", "65.5", "6553.5"}


@pytest.fixture(scope="module")
def values() -> list[float]:
    found = set()
    for path in (ROOT / "results").rglob("*"):
        if path.is_file() and path.suffix in (".csv", ".json", ".md", ".txt", ".toml"):
            for match in NUMBER.finditer(path.read_text(errors="replace")):
                try:
                    found.add(float(match.group(0)))
                except ValueError:
                    continue
    return sorted(found)


def held(figure: str, values: list[float]) -> bool:
    """Whether some value rounds to ``figure`` at its decimals."""
    half = 0.5 * 10.0 ** -len(figure.split(".")[1])
    x = float(figure)
    i = bisect.bisect_left(values, x - half)
    return i < len(values) and values[i] <= x + half


@pytest.mark.parametrize("page", PAGES)
def test_every_figure_is_in_a_results_file(page, values):
    missing = [f"{page}:{n}: {m.group(0)}"
               for n, line in enumerate((ROOT / page).read_text().splitlines(), 1)
               for m in FIGURE.finditer(line) if m.group(0) not in CONSTANTS
               and not held(m.group(0), values)]
    assert not missing, "figures no results file holds:\n" + "\n".join(missing)


def test_the_check_fails_on_a_figure_no_file_holds(values):
    assert held("25.91", values)  # results/example/object.json's PSNR
    assert not held("12345.678", values)


def test_the_readme_stays_short():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 300
