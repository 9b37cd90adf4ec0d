"""Session-wide test fixtures.

Every compiled XLA:CPU executable keeps a few memory mappings (about 3), and JAX keeps
every executable the session compiled, eager operations on a new shape included. The
whole suite compiles enough of them to approach Linux's limit on mappings per process
(``vm.max_map_count``, 65530 by default); past it the next compilation segfaults inside
XLA (seen twice in a full run, in ``backend_compile_and_load`` and in a persistent-cache
read). Between tests, once the process holds more than :data:`MAX_MAPPINGS`, JAX's
caches are cleared: the executables are freed, and tests that need them again compile
them again (or load them from the persistent compilation cache).

The suite never writes into a user's caches (``~/.cache/vbgs``: compiled executables,
resized photos): unless ``VBGS_CACHE_DIR`` or ``VBGS_COMPILE_CACHE`` is set, the session
points ``VBGS_CACHE_DIR`` at a temporary folder, which the commands the tests start in
subprocesses inherit, and removes it at the end. Under pytest-xdist (``-n 2``, the
default options in pyproject.toml) the controlling process makes the folder before it
starts the workers, which inherit it: the workers share one persistent compilation
cache, and each checks its own mappings.

Each process that runs tests (each xdist worker, or the one process under ``-n 0``) turns
that persistent cache on before its first test, as every command line does: an executable
one worker compiled is loaded, not compiled again, by the other worker, by the commands
tests start in subprocesses, and by the same worker after its caches were cleared. (Before,
a worker turned it on only when a test first called ``experiments.run.main`` in-process, so
which compiles were shared depended on the order the files ran in.)
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest

MAPS = Path("/proc/self/maps")
MAX_MAPPINGS = 30000  # about half of the default vm.max_map_count


_SESSION_CACHE: list[str] = []


def pytest_configure(config):
    if not (os.environ.get("VBGS_CACHE_DIR") or os.environ.get("VBGS_COMPILE_CACHE")):
        folder = tempfile.mkdtemp(prefix="vbgs-test-cache-")
        os.environ["VBGS_CACHE_DIR"] = folder
        _SESSION_CACHE.append(folder)
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        from vbgs.compilation import enable_persistent_cache

        enable_persistent_cache()  # the xdist controller runs no test: it needs no JAX


def pytest_unconfigure(config):
    while _SESSION_CACHE:
        folder = _SESSION_CACHE.pop()
        os.environ.pop("VBGS_CACHE_DIR", None)
        shutil.rmtree(folder, ignore_errors=True)


def mappings() -> int:
    """The memory mappings this process holds (0 where /proc is not there)."""
    try:
        with MAPS.open("rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return 0


@pytest.fixture(autouse=True)
def _free_executables_before_the_mapping_limit():
    yield
    if mappings() > MAX_MAPPINGS:
        import jax

        jax.clear_caches()
