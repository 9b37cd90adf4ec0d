"""2-D image rendering of a fitted mixture: the colour expected at each pixel.

The 3-D splat rasterizer lives in :mod:`vbgs.render.raster`.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.model import (
    Mixture,
    bucket_size,
    chunk_size,
    feature_logits,
    features,
    log_joint_weights,
)
from vbgs.inference.precision import matmul
from vbgs.render.pixels import pixel_centres


@partial(jax.jit, static_argnames=("chunk",))
def _expected_colour(q: Mixture, x: jnp.ndarray, chunk: int) -> jnp.ndarray:
    weights = log_joint_weights(q, colour_noise=None)  # [k, F]

    def one_chunk(xb):
        logits = feature_logits(features(xb, None), weights)  # [chunk, k], full float32
        return matmul(jax.nn.softmax(logits, -1), q.colour.mean)  # [chunk, 3]

    out = jax.lax.map(one_chunk, x.reshape(-1, chunk, x.shape[-1]))
    return out.reshape(-1, 3)


def expected_colour(q: Mixture, xy) -> np.ndarray:
    """``E[c | x] = sum_k p(k | x) E[mu_c,k]`` at positions ``xy [n, d]`` (world units),
    with ``p(k | x) = softmax_k(E[log pi_k] + E[log N(x | mu_k, Sigma_k)])`` — the
    E-step's responsibilities with the colour left out. Returns ``[n, 3]`` on the host
    (centring, padding and slicing in numpy: eager device operations would each
    compile)."""
    dtype = np.dtype(q.alpha.dtype)
    x = np.asarray(xy, dtype) - np.asarray(q.origin, dtype)  # [n, d]
    n = x.shape[0]
    size = bucket_size(n)
    x = np.pad(x, ((0, size - n), (0, 0)))
    chunk = chunk_size(size, q.n_components)
    return np.asarray(_expected_colour(q, x, chunk))[:n]


def render_image(q: Mixture, height: int, width: int) -> np.ndarray:
    """Render a 2-D mixture fitted on pixel centres to an image ``[h, w, 3]`` in [0, 1]."""
    rgb = expected_colour(q, pixel_centres(height, width))
    return np.clip(rgb, 0.0, 1.0).reshape(height, width, 3)
