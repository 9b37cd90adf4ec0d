"""Compilation: JAX's persistent compilation cache, and how long compiling took.

A fresh process pays XLA compilation for every function and every shape it runs,
although nothing changed since the last run. :func:`enable_persistent_cache` keeps
compiled executables on disk (``$XDG_CACHE_HOME/vbgs/jax``, by default
``~/.cache/vbgs/jax``) so a second identical run loads them instead; set
``VBGS_NO_COMPILE_CACHE=1`` to opt out, or ``VBGS_COMPILE_CACHE=DIR`` to move it.
:func:`cache_root` is the folder of the CLI's other caches (resized photos, ``images``);
``VBGS_CACHE_DIR=DIR`` moves all of them (the test suite points it at a temporary
folder, so tests never write into a user's cache).
:class:`CompileTimer` sums the compile events JAX reports (tracing, lowering, backend
compile or cache load) so results can report compile time apart from run time.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)

_lock = threading.Lock()
_total = [0.0]
_listening = [False]


def cache_root() -> Path | None:
    """The CLI's cache folder: ``$VBGS_CACHE_DIR`` when set, else
    ``$XDG_CACHE_HOME/vbgs`` (``~/.cache/vbgs``); None when ``VBGS_NO_COMPILE_CACHE``
    opts out of caching."""
    if os.environ.get("VBGS_NO_COMPILE_CACHE", "").strip() not in ("", "0"):
        return None
    if os.environ.get("VBGS_CACHE_DIR"):
        return Path(os.environ["VBGS_CACHE_DIR"]).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "vbgs"


def cache_dir() -> Path | None:
    """Where the persistent cache lives, or None when opted out."""
    root = cache_root()
    if root is None:
        return None
    if os.environ.get("VBGS_COMPILE_CACHE"):
        return Path(os.environ["VBGS_COMPILE_CACHE"]).expanduser()
    return root / "jax"


def enable_persistent_cache() -> Path | None:
    """Turn on JAX's persistent compilation cache (every executable, however quick to
    compile); returns the folder, or None when ``VBGS_NO_COMPILE_CACHE`` is set."""
    import jax  # here, not at import: a sweep reads cache_dir() before its workers
    #             set their thread limits and import JAX

    folder = cache_dir()
    if folder is None:
        return None
    folder.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return folder


def _listen(event: str, seconds: float, **_) -> None:
    if event in COMPILE_EVENTS:
        with _lock:
            _total[0] += seconds


def compile_seconds() -> float:
    """Seconds spent compiling in this process since the first :class:`CompileTimer`."""
    with _lock:
        return _total[0]


class CompileTimer:
    """``with CompileTimer() as t: ...``; then ``t.seconds`` is the compile time inside."""

    def __init__(self):
        if not _listening[0]:
            import jax

            jax.monitoring.register_event_duration_secs_listener(_listen)
            _listening[0] = True
        self.seconds = 0.0

    def __enter__(self):
        self._start = compile_seconds()
        return self

    def __exit__(self, *exc):
        self.seconds = compile_seconds() - self._start
        return False
