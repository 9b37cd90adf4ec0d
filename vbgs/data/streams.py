"""Orders in which frames or patches are streamed to a continual learner."""

from __future__ import annotations

import numpy as np

ORDERS = ("sequential", "shuffled", "reversed")


def stream_order(n: int, order: str = "sequential", *, seed: int = 0) -> np.ndarray:
    """Indices ``[n]`` visiting n items in the given order.

    sequential: 0..n-1 (raster order for patches, trajectory order for frames);
    shuffled: a permutation drawn from ``seed``; reversed: n-1..0.
    """
    if order not in ORDERS:
        raise ValueError(f"unknown stream order {order!r}: choose one of {', '.join(ORDERS)}")
    if n < 0:
        raise ValueError(f"cannot order a negative number of items ({n})")
    idx = np.arange(n)
    if order == "shuffled":
        return np.random.default_rng(seed).permutation(n)
    if order == "reversed":
        return idx[::-1].copy()
    return idx
