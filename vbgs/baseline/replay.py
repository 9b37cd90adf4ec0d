"""Replay buffers for continual training: which past frames a gradient learner keeps.

Kinds (the spec strings :func:`parse_replay` reads):

* ``none``: keeps nothing;
* ``fifo:K``: the last K frames added;
* ``reservoir:K``: a uniform random sample of K of all frames added so far
  (Vitter's Algorithm R: item i, counting from 0, is kept outright while i < K,
  else it replaces slot j when ``j ~ U{0..i}`` falls below K; every item seen then
  stays with probability K / n). The draw for item i uses its own generator
  seeded by ``(seed, i)``, so a buffer is a pure function of its items and seed;
* ``full``: every frame.

A buffer is immutable: ``buffer = buffer.add(frame)``. Its ``nbytes`` counts the
``rgb`` and ``depth`` arrays of the frames it holds (cameras are a few numbers).
The trainer draws each step's frame uniformly from ``{current frame} ∪ buffer``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

KINDS = ("none", "fifo", "reservoir", "full")
SIZED = ("fifo", "reservoir")
SPEC_HELP = "use 'none', 'full', 'fifo:K' or 'reservoir:K' with K a positive integer"


def item_bytes(item) -> int:
    """Bytes of an item's ``rgb`` and ``depth`` arrays and its depth weights when it has
    them (numpy or JAX; a plain array counts itself)."""
    if hasattr(item, "rgb"):
        weight = getattr(item, "pixel_weight", None)
        return int(item.rgb.nbytes + item.depth.nbytes
                   + (0 if weight is None else weight.nbytes))
    return int(np.asarray(item).nbytes)


@dataclass(frozen=True)
class Replay:
    """An immutable replay buffer (see the module docstring)."""

    kind: str = "none"
    size: int | None = None  # K for fifo/reservoir
    seed: int = 0
    items: tuple = ()
    seen: int = 0  # items ever added

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"unknown replay kind {self.kind!r}: {SPEC_HELP}")
        if (self.kind in SIZED) != (self.size is not None):
            raise ValueError(f"replay {self.kind!r} with size {self.size!r}: {SPEC_HELP}")
        if self.size is not None and (not isinstance(self.size, int) or self.size < 1):
            raise ValueError(f"replay size must be a positive integer, got {self.size!r}")

    def add(self, item) -> Replay:
        """The buffer after ``item`` arrives."""
        i, items = self.seen, self.items
        if self.kind == "full" or (self.kind in SIZED and len(items) < self.size):
            items = items + (item,)
        elif self.kind == "fifo":
            items = items[1:] + (item,)
        elif self.kind == "reservoir":
            j = int(np.random.default_rng([self.seed, i]).integers(0, i + 1))
            if j < self.size:
                items = items[:j] + (item,) + items[j + 1 :]
        return replace(self, items=items, seen=i + 1)

    @property
    def nbytes(self) -> int:
        """Bytes of the frames held (rgb + depth arrays)."""
        return sum(item_bytes(it) for it in self.items)

    def __len__(self) -> int:
        return len(self.items)

    @property
    def spec(self) -> str:
        """The spec string this buffer was made from (``fifo:8``...)."""
        return self.kind if self.size is None else f"{self.kind}:{self.size}"


def parse_replay(spec: str, *, seed: int = 0) -> Replay:
    """An empty buffer from a spec string: ``none``, ``full``, ``fifo:K``, ``reservoir:K``."""
    if not isinstance(spec, str):
        raise TypeError(f"replay spec must be a string, got {type(spec).__name__}: {SPEC_HELP}")
    kind, sep, size = spec.strip().lower().partition(":")
    if kind not in KINDS:
        raise ValueError(f"unknown replay {spec!r}: {SPEC_HELP}")
    if kind in SIZED:
        if not sep or not size.strip().isdigit() or int(size) < 1:
            raise ValueError(
                f"replay {spec!r} needs a size: write {kind}:K with K a positive integer, "
                f"e.g. {kind}:8"
            )
        return Replay(kind, int(size), seed)
    if sep:
        raise ValueError(f"replay {kind!r} takes no size, got {spec!r}: {SPEC_HELP}")
    return Replay(kind, None, seed)
