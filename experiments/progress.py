"""Progress for every command: a tqdm bar on a terminal, plain log lines elsewhere.

A bar redraws in place, which a log file or a CI console shows as nothing (or as a
mess) for minutes. When stderr is not a terminal, :class:`LogLines` writes a line
when the work starts (the first items compile: ``frames 0/60: compiling ...``) and
then one every :data:`LOG_EVERY` seconds, ``frames 12/60, 3.4 frames/s, 14 s left``
(the rate measured after the first item, which carries the compilation).
"""

from __future__ import annotations

import sys
import time

LOG_EVERY = 5.0  # seconds between log lines


class LogLines:
    """A tqdm-like counter (iterate it, or ``update(n)``; ``n``, ``close``) that writes
    plain lines to ``stream`` (None: silent)."""

    def __init__(self, iterable=None, total=None, desc: str = "", unit: str = "it",
                 stream=sys.stderr, every: float = LOG_EVERY, clock=time.monotonic,
                 compiles: bool = True):
        self.iterable, self.desc, self.unit, self.stream = iterable, desc, unit, stream
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = len(iterable)
        self.total, self.every, self.clock, self.n = total, every, clock, 0
        self.start = self.last = clock()
        self.first_done: float | None = None
        self.lines = 0
        self._say(f"{self._count()}: compiling on the first {unit} (or loading the compile "
                  f"cache) ..." if compiles else f"{self._count()} ...")

    def __len__(self):
        return self.total

    def __iter__(self):
        for item in self.iterable:
            yield item
            self.update(1)
        self.close()

    def _count(self) -> str:
        return f"{self.desc} {self.n}/{self.total}" if self.total else f"{self.desc} {self.n}"

    def _say(self, line: str) -> None:
        if self.stream is not None:
            print(line, file=self.stream, flush=True)
            self.lines += 1

    def update(self, n: int = 1) -> None:
        self.n += n
        now = self.clock()
        if self.first_done is None:
            self.first_done, self.n_first = now, self.n
        if now - self.last < self.every:
            return
        self.last = now
        line = self._count()
        done, spent = self.n - self.n_first, now - self.first_done
        if done > 0 and spent > 0:
            rate = done / spent
            line += f", {rate:.3g} {self.unit}s/s"
            if self.total:
                line += f", {max(self.total - self.n, 0) / rate:.0f} s left"
        self._say(line)

    def set_postfix(self, *args, **kwargs) -> None:
        """Accepted for tqdm's interface; log lines carry no postfix."""

    def close(self) -> None:
        if self.stream is not None and self.lines > 1:  # said more than the start: the end
            self._say(f"{self._count()} done in {self.clock() - self.start:.0f} s")
            self.stream = None


def progress(iterable=None, *, total=None, desc: str = "", unit: str = "it",
             enabled: bool = True, leave: bool = False, compiles: bool = True):
    """The progress of a loop: a tqdm bar when stderr is a terminal, else log lines;
    silent when not ``enabled``. ``compiles``: the first item compiles (the log's first
    line says so)."""
    if enabled and sys.stderr.isatty():
        from tqdm.auto import tqdm

        return tqdm(iterable, total=total, desc=desc, unit=unit, leave=leave)
    return LogLines(iterable, total, desc, unit, sys.stderr if enabled else None,
                    compiles=compiles)


def write(line: str) -> None:
    """A line on stderr that does not break a bar on a terminal."""
    from tqdm.auto import tqdm

    tqdm.write(line, file=sys.stderr)
