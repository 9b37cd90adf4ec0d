"""Where a frame's time goes: an opt-in timer of the mapper's stages.

JAX dispatches device work asynchronously, so a host profiler charges a stage's device
time to whichever later line first waits for it. Inside :func:`timing`, each stage of
:func:`vbgs.mapping.update` waits for what it produced before its clock stops, so each
stage is charged its own work (the price: no overlap of host and device work, so the
sum is a little more than an untimed frame). A stage inside another (``merge``, inside
``grow``) is charged to its own name and left out of the outer one's. Outside it,
:func:`stage` costs a function call and times nothing::

    with stages.timing() as seconds:
        state, info = learner.update(state, frame)
    seconds   # {"prepare": ..., "merge": ..., "grow": ..., "search+step": ..., "evidence": ...}
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager

import jax

_seconds: list[dict[str, float] | None] = [None]
_open: list[_Stage] = []  # the stages being timed, outermost first


@contextmanager
def timing() -> Iterator[dict[str, float]]:
    """Time the stages run inside: yields the dict of seconds per stage it fills."""
    before, _seconds[0] = _seconds[0], {}
    try:
        yield _seconds[0]
    finally:
        _seconds[0] = before


class _Stage:
    __slots__ = ("outputs", "inner")

    def __init__(self):
        self.outputs = []
        self.inner = 0.0  # seconds of the stages inside this one

    def __call__(self, *trees):
        """Register what the stage produced (its clock stops when that is ready)."""
        self.outputs.extend(trees)
        return trees[0] if len(trees) == 1 else trees


@contextmanager
def stage(name: str) -> Iterator[_Stage]:
    """Charge the time inside to ``name`` when :func:`timing` is on (after waiting for
    the arrays passed to the yielded callable)."""
    s = _Stage()
    seconds = _seconds[0]
    if seconds is None:
        yield s
        return
    t0 = time.perf_counter()
    _open.append(s)
    try:
        yield s
    finally:
        _open.pop()
    jax.block_until_ready([o for o in s.outputs if o is not None])
    spent = time.perf_counter() - t0
    seconds[name] = seconds.get(name, 0.0) + spent - s.inner
    if _open:  # a stage inside another: charged to its own name, not twice
        _open[-1].inner += spent
