"""An image's neighbours as whole shifted images, for compiled per-pixel filters.

A filter over a window of pixel offsets (the holes' fill, :mod:`vbgs.mapping.holes`; the
depth's averaging, :mod:`vbgs.mapping.denoise`) reads, for each offset, the image shifted
by it. The image is padded once with the value outside it (:func:`padded`) and each shift
is a slice of the padded copy (:func:`shifted`): static offsets unrolled under ``jit``,
which XLA fuses into one pass over the pixels.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def padded(a: jax.Array, pad: int, fill=0.0) -> jax.Array:
    """``a [h, w, ...]`` with ``pad`` pixels of ``fill`` about its first two axes."""
    return jnp.pad(a, ((pad, pad), (pad, pad)) + ((0, 0),) * (a.ndim - 2),
                   constant_values=fill)


def shifted(padded: jax.Array, pad: int, dy: int, dx: int, h: int, w: int) -> jax.Array:
    """``out[y, x] = a[y + dy, x + dx]`` for ``padded``: ``a [h, w, ...]`` padded by
    ``pad`` pixels on each side with the value outside the image (``|dy|, |dx| <= pad``)."""
    return jax.lax.slice_in_dim(jax.lax.slice_in_dim(padded, pad + dy, pad + dy + h, axis=0),
                                pad + dx, pad + dx + w, axis=1)
