"""Atomic file writes: a file that exists under its final name is complete.

Every writer puts its bytes in a temporary file in the same folder (same file
system, so the rename is atomic), then ``os.replace`` moves it onto the final
name. An error or Ctrl-C (``KeyboardInterrupt``) while writing removes the
temporary file and leaves any earlier file at the final name untouched.

The temporary name starts with a dot and keeps the final suffix
(``.frame_00.<pid>.<token>.tmp.png``), so writers that pick the format from the
suffix (scikit-image, matplotlib, plyfile) still work; readers that glob a folder
should skip names starting with a dot.

Used by ``depth`` (depth PNGs, preview), ``vbgs.data`` (dataset writer) and
``experiments`` (sweep records, reports); it imports nothing from them.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path


def temporary_name(path: str | Path) -> Path:
    """A hidden name beside ``path`` for its temporary file, unique per process and call."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp{path.suffix}")


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; on a clean exit it replaces ``path``.

    The parent folder is created if missing. On any exception (including
    ``KeyboardInterrupt``) the temporary file is removed and ``path`` is unchanged.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_atomic(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp)`` to write a temporary file, then move it onto ``path``.

    Returns ``path``.
    """
    with atomic_path(path) as tmp:
        write(tmp)
    return Path(path)


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; return ``path``."""
    return write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
