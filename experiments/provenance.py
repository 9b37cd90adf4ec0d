"""Which code and which command made a results file.

Every JSON record a command prints or writes carries ``code_version`` and ``command``
(:func:`stamp`), and every markdown table it writes starts with one line naming both
(:func:`first_line`). ``code_version`` is the short commit of the checkout the code runs
from, with ``+dirty`` when tracked code (``vbgs``, ``depth``, ``experiments``,
``pyproject.toml``) differs from that commit or holds files not yet committed, and
``unknown`` outside a git checkout. ``command`` is the command line as run: what
``experiments.run.main`` was given (:func:`record_command`), else the process's own
``sys.argv``. A JSON record also names the ``environment`` it ran in (:func:`environment`):
the same code and command give the same figures to the last bit only on the same kind of
CPU under the same versions of the numeric packages (the object at fit-scene's defaults,
at one code: 25.91227 dB where its first record was made, 25.91528 on an Intel Xeon with
a later install).
"""

from __future__ import annotations

import functools
import json
import platform
import re
import shlex
import subprocess
import sys
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CODE_PATHS = ("vbgs", "depth", "experiments", "pyproject.toml")
# The packages whose versions move a figure's last bits (numeric kernels, KD-trees).
NUMERIC_PACKAGES = ("jax", "jaxlib", "numpy", "scipy")
UNKNOWN = "unknown"

_command: str | None = None


def git(*args, root: str | Path = ROOT) -> str:
    """``git -C root ARGS``'s output, stripped (raises ``CalledProcessError`` on failure,
    ``OSError`` where git is missing)."""
    return subprocess.run(["git", "-C", str(root), *args], capture_output=True,
                          text=True, timeout=60, check=True).stdout.strip()


@functools.cache
def code_version(root: str | Path = ROOT) -> str:
    """``git rev-parse --short HEAD`` of ``root``, ``+dirty`` when its code differs from
    that commit; ``unknown`` when ``root`` is not a git checkout (or git is missing)."""
    try:
        head = git("rev-parse", "--short", "HEAD", root=root)
        changed = git("status", "--porcelain", "--", *CODE_PATHS, root=root)
    except (OSError, subprocess.SubprocessError):
        return UNKNOWN
    return head + ("+dirty" if changed else "")


def record_command(argv: list[str], program: str = "python -m experiments.run") -> None:
    """Remember the command line being run: ``program`` followed by ``argv``."""
    global _command
    _command = " ".join([program, shlex.join(argv)]) if argv else program
    code_version()  # read now, as the code starts: a commit made while it runs is not its


def command() -> str:
    """The command line as run (:func:`record_command`; else this process's argv, a
    module run with ``-m`` named as such)."""
    if _command is not None:
        return _command
    first = Path(sys.argv[0]) if sys.argv and sys.argv[0] else None
    if first is not None and first.suffix == ".py" and ROOT in first.resolve().parents:
        module = ".".join(first.resolve().relative_to(ROOT).with_suffix("").parts)
        return " ".join(["python -m " + module, shlex.join(sys.argv[1:])]).strip()
    if sys.argv and sys.argv[0] == "-c":
        return " ".join(["python -c ...", shlex.join(sys.argv[1:])]).strip()
    return shlex.join(sys.argv) if sys.argv else UNKNOWN


@functools.cache
def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what :mod:`platform` says."""
    try:
        with open("/proc/cpuinfo") as f:
            return next(line.split(":", 1)[1].strip() for line in f
                        if line.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


@functools.cache
def environment() -> str:
    """The CPU, Python's version and those of :data:`NUMERIC_PACKAGES`, one line."""
    def version(name):
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "absent"

    return ", ".join([cpu_model(), f"Python {platform.python_version()}",
                      *(f"{name} {version(name)}" for name in NUMERIC_PACKAGES)])


def stamp(record: dict) -> dict:
    """``record`` with ``code_version``, ``command`` and ``environment`` (the record's own
    kept first)."""
    return {**record, "code_version": record.get("code_version", code_version()),
            "command": record.get("command", command()),
            "environment": record.get("environment", environment())}


def first_line() -> str:
    """The line a markdown table starts with: the command and the code version."""
    return f"Made by `{command()}` at code `{code_version()}`."


FIRST_LINE = re.compile(r"^Made by `(?P<command>[^`]+)` at code `(?P<version>[^`]+)`\.$")


def is_stamped_json(record) -> bool:
    """Whether a JSON record names a code version and a command."""
    return (isinstance(record, dict) and bool(record.get("code_version"))
            and bool(record.get("command")))


def is_stamped_markdown(text: str) -> bool:
    """Whether a markdown file's first line names a command and a code version."""
    return FIRST_LINE.match(text.split("\n", 1)[0]) is not None


def recorded(path: Path) -> tuple[str, str] | None:
    """The command and code version a results file (``.json`` or ``.md``) records, or
    None where it records none (a JSON file that does not parse records none)."""
    text = path.read_text()
    if path.suffix == ".json":
        try:
            record = json.loads(text)
        except ValueError:
            return None
        return (record["command"], record["code_version"]) if is_stamped_json(record) else None
    match = FIRST_LINE.match(text.split("\n", 1)[0]) if path.suffix == ".md" else None
    return (match["command"], match["version"]) if match else None
