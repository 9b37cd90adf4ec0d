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

Most of the suite's CPU time is XLA compiling small functions that then run for a moment
on small inputs. When the run leaves the slow tests out (``-m 'not slow'``,
the default options), unless ``VBGS_TEST_XLA_OPTIMISE=1`` is set (or ``XLA_FLAGS`` already
sets an optimisation level), the session adds :data:`FAST_COMPILE_FLAGS` to ``XLA_FLAGS`` before
any JAX computation, so the workers and the commands tests start in subprocesses compile
fusions with XLA:CPU's older LLVM IR emitters instead of its MLIR fusion emitters, and
without LLVM's optimisation passes. Measured on the shared 2-core machine (``-n 0``,
test_stability.py with test_raster_pallas.py, user CPU seconds): XLA's default 63.0;
level 0 alone 47.8; level 0 and no expensive passes 42.7 (44.3 in a second run); the old
emitters alone 39.5; the old emitters and level 0 21.1; all three 20.1. The whole default
run (``/usr/bin/time -v python -m pytest -q``, one run straight after the other on the
loaded machine): at XLA's default 1132 s user+sys CPU, 1128 s wall; fast 455 s, 444 s
(1095 passed, 1 skipped, both). Only on a
CPU-only install: a GPU's kernels keep XLA's default (where a CUDA plugin is installed, or
``JAX_PLATFORMS`` names a GPU). The slow tests (long streams: more running than compiling,
their floors measured at XLA's default) keep XLA's default too.

A few tests hold two compiled paths equal to the bit, which they are at XLA's default
optimisation and are not under :data:`FAST_COMPILE_FLAGS` (the fusions round
differently: the compiled fit against its host loop, 4e-5 relative in a mean; a merge's
untouched components, 1.2e-4 in a scatter entry left by cancellation). Marked
``@pytest.mark.xla_default``, such a test runs in a fresh process at XLA's default when
the session compiles fast (:func:`pytest_pyfunc_call`).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

MAPS = Path("/proc/self/maps")
MAX_MAPPINGS = 30000  # about half of the default vm.max_map_count


_SESSION_CACHE: list[str] = []

FAST_COMPILE_FLAGS = ("--xla_cpu_use_fusion_emitters=false",
                      "--xla_backend_optimization_level=0",
                      "--xla_llvm_disable_expensive_passes=true")
CUDA_PLUGINS = ("jax_cuda12_plugin", "jax_cuda13_plugin", "jax_plugins.xla_cuda12")


def _cpu_only() -> bool:
    if any(p in os.environ.get("JAX_PLATFORMS", "") for p in ("cuda", "gpu", "rocm")):
        return False
    for name in CUDA_PLUGINS:
        try:
            if importlib.util.find_spec(name) is not None:
                return False
        except ModuleNotFoundError:  # a dotted name whose parent is not installed
            continue
    return True


def compile_fast(environ=os.environ) -> None:
    """Add :data:`FAST_COMPILE_FLAGS` to ``environ["XLA_FLAGS"]`` (see the module's
    docstring for when)."""
    flags = environ.get("XLA_FLAGS", "")
    if (environ.get("VBGS_TEST_XLA_OPTIMISE", "").strip() not in ("", "0")
            or "xla_backend_optimization_level" in flags or not _cpu_only()):
        return
    environ["XLA_FLAGS"] = " ".join([flags, *FAST_COMPILE_FLAGS]).strip()


def compiles_fast(environ=os.environ) -> bool:
    """Whether this process compiles with :data:`FAST_COMPILE_FLAGS`."""
    return FAST_COMPILE_FLAGS[0] in environ.get("XLA_FLAGS", "").split()


def xla_default_environ(environ=os.environ) -> dict:
    """``environ`` for a process that compiles at XLA's default and caches nothing."""
    flags = [f for f in environ.get("XLA_FLAGS", "").split() if f not in FAST_COMPILE_FLAGS]
    return {**environ, "XLA_FLAGS": " ".join(flags), "VBGS_TEST_XLA_OPTIMISE": "1",
            "VBGS_NO_COMPILE_CACHE": "1"}


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem):
    """A test marked ``xla_default`` runs in a fresh process at XLA's default (the module's
    docstring) when this one compiles fast; its result is that process's."""
    if pyfuncitem.get_closest_marker("xla_default") is None or not compiles_fast():
        return None
    root = Path(__file__).resolve().parents[1]
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p",
                          "no:cacheprovider", "--durations=0", pyfuncitem.nodeid],
                         capture_output=True, text=True, cwd=root,
                         env=xla_default_environ(), timeout=600)
    if run.returncode != 0:
        pytest.fail(f"at XLA's default optimisation:\n{run.stdout[-4000:]}{run.stderr[-2000:]}",
                    pytrace=False)
    return True


def pytest_configure(config):
    if "not slow" in (config.getoption("markexpr", "") or ""):
        compile_fast()
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
