"""Test helper: emulate TF32 matrix products on the CPU.

On NVIDIA GPUs a float32 ``dot_general`` at default precision rounds both operands to a
10-bit mantissa (TF32) and accumulates in float32. :func:`emulated_tf32` patches JAX's
``dot_general`` so that, inside the ``with`` block, every product that does not ask for
``Precision.HIGHEST`` rounds its float32 operands the same way first.

Each block traces afresh and its traces are never reused outside it: a JAX user context
(part of every jit cache key) takes a new value per block. ``jax.clear_caches()`` did
the same, but threw away every executable the test session had compiled (in the whole
suite, the first clear alone took longer than these tests).
"""

from __future__ import annotations

import contextlib
import itertools

import jax
import jax.numpy as jnp
from jax._src.lax import lax as _lax


def round_tf32(x: jnp.ndarray) -> jnp.ndarray:
    """Round float32 values to the nearest TF32 value (10 mantissa bits, ties to even)."""
    if x.dtype != jnp.float32:
        return x
    bits = jax.lax.bitcast_convert_type(x, jnp.uint32)
    lsb = (bits >> 13) & 1
    bits = (bits + jnp.uint32(0x0FFF) + lsb) & jnp.uint32(0xFFFFE000)
    return jax.lax.bitcast_convert_type(bits, jnp.float32)


def _is_full(precision) -> bool:
    full = (jax.lax.Precision.HIGHEST,)
    if isinstance(precision, tuple):
        return all(p in full for p in precision)
    return precision in full


_block = jax.make_user_context(default_value=None)  # None outside every block
_blocks = itertools.count(1)


@contextlib.contextmanager
def emulated_tf32():
    """Inside the block, default-precision float32 products see TF32-rounded operands."""
    original = _lax.dot_general

    def dot_general(lhs, rhs, dimension_numbers, precision=None, *args, **kwargs):
        if not _is_full(precision):
            lhs, rhs = round_tf32(jnp.asarray(lhs)), round_tf32(jnp.asarray(rhs))
        return original(lhs, rhs, dimension_numbers, precision, *args, **kwargs)

    _lax.dot_general = dot_general
    try:
        with _block(next(_blocks)):  # this block's own traces (a test may patch more)
            yield
    finally:
        _lax.dot_general = original
