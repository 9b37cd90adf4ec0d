"""Matrix products at full float32 precision, for the numerically delicate ones.

On NVIDIA GPUs JAX runs float32 matrix products in TF32 by default: each operand is
rounded to a 10-bit mantissa (relative error up to ``2^-11``) before the product. The
E-step's log-likelihood in feature form,
``l_nk = phi_n . W_k = -1/2 x^T P_k x + x^T P_k m_k + c_k``, adds terms that are each far
larger than their sum (they cancel to ``-1/2 (x - m_k)^T P_k (x - m_k)``): with
``|x| ~ 30`` cell lengths an operand error of ``2^-11`` on ``P x^2 / 2 ~ 450`` moves a
logit by about 0.2 and a 256 px image fit collapses onto a handful of components.

Two protections are used, and each function says which it relies on:

* **explicit precision**: every product in feature form goes through :func:`matmul`,
  which asks XLA for ``Precision.HIGHEST`` (true float32 on every backend);
* **centred form**: where the products are few per point (the sparse E-step, quadratic
  forms over ``d x d`` matrices), they are written as elementwise products and sums of
  centred quantities such as ``x - m_k``; elementwise arithmetic is never rounded to TF32.

``PRODUCT_PRECISION`` is read when a function is traced; tests set it to ``DEFAULT`` to
show what the protection buys (see ``tests/vbgs/inference/test_precision.py``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

PRODUCT_PRECISION = jax.lax.Precision.HIGHEST


def matmul(a: jnp.ndarray, b: jnp.ndarray) -> jnp.ndarray:
    """``a @ b`` at :data:`PRODUCT_PRECISION` (full float32 unless a test lowers it)."""
    return jnp.matmul(a, b, precision=PRODUCT_PRECISION)


def tensordot(a: jnp.ndarray, b: jnp.ndarray, axes) -> jnp.ndarray:
    """``jnp.tensordot(a, b, axes)`` at :data:`PRODUCT_PRECISION`."""
    return jnp.tensordot(a, b, axes=axes, precision=PRODUCT_PRECISION)


def quad_form(diff: jnp.ndarray, prec: jnp.ndarray) -> jnp.ndarray:
    """``diff^T P diff`` over the last axis, ``diff [..., d]``, ``prec [..., d, d]`` -> ``[...]``,
    as elementwise products and sums (centred form: no matrix-unit rounding)."""
    return jnp.sum(diff[..., :, None] * prec * diff[..., None, :], axis=(-1, -2))


def mat_vec(mat: jnp.ndarray, vec: jnp.ndarray) -> jnp.ndarray:
    """``M v`` over the last axes, ``mat [..., d, d]``, ``vec [..., d]`` -> ``[..., d]``, as
    elementwise products and a sum (no matrix-unit rounding)."""
    return jnp.sum(mat * vec[..., None, :], axis=-1)


def logdet3(s, floor: float = 0.0):
    """``log max(|det s|, floor)`` ``[...]`` of ``s [..., 3, 3]``, elementwise by the rule of Sarrus
    (numpy in, numpy out; JAX in, JAX out). Batched LAPACK costs far more for 3x3
    matrices: ``jnp.linalg.slogdet`` took 4.2 ms of CPU for 20000 of them, this 0.04 ms.
    The absolute value, as ``slogdet``'s: a thin component's float32 scale matrix can
    come out slightly indefinite. Precision: the determinant is a sum of three products
    of a matrix entry and a 2x2 minor, so a nearly singular (thin) matrix loses about
    ``eps * |s|^3 / |det s|`` relative accuracy, as an LU factorisation does."""
    xp = jnp if isinstance(s, jax.Array) else np
    det = (s[..., 0, 0] * (s[..., 1, 1] * s[..., 2, 2] - s[..., 1, 2] * s[..., 2, 1])
           - s[..., 0, 1] * (s[..., 1, 0] * s[..., 2, 2] - s[..., 1, 2] * s[..., 2, 0])
           + s[..., 0, 2] * (s[..., 1, 0] * s[..., 2, 1] - s[..., 1, 1] * s[..., 2, 0]))
    return xp.log(xp.maximum(xp.abs(det), floor))
