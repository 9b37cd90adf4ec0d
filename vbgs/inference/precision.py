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

from typing import NamedTuple

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



class LDL3(NamedTuple):
    """``s = L D L^T`` of symmetric 3x3 matrices ``s [..., 3, 3]``: ``L`` unit lower
    triangular with entries ``l10, l20, l21`` and ``D = diag(d0, d1, d2)``, each
    ``[...]``. One array per entry: elementwise arithmetic over a trailing axis of 3
    vectorises badly on CPUs (the along-ray test of 100k components' five rays took 80
    ms in ``[..., 3]`` arrays, 2.5 ms in these)."""

    l10: jnp.ndarray
    l20: jnp.ndarray
    l21: jnp.ndarray
    d0: jnp.ndarray
    d1: jnp.ndarray
    d2: jnp.ndarray


def ldl3(s: jnp.ndarray) -> LDL3:
    """:class:`LDL3` of ``s [..., 3, 3]``, elementwise (JAX): with
    :func:`unit_lower_solve3`, ``u^T s^-1 v = sum_i (L^-1 u)_i (L^-1 v)_i / d_i``.

    Why not an inverse: a batched LAPACK inverse of 3x3 matrices costs far more than
    their arithmetic (about 100 ms of CPU for 100000), and the adjugate's inverse,
    elementwise too, loses a nearly singular (thin) matrix's quadratic forms: at unit
    trace, one axis 1e-6 of the others, ``r^T s^-1 r`` came out up to 16 times off where
    this is within 1.2% of float64, as LAPACK's float32 inverse (0.9%). Precision:
    symmetric positive definite ``s`` factor stably without pivoting; an indefinite one
    gives a negative ``d_i``, and the caller decides what that means."""
    l10, l20 = s[..., 1, 0] / s[..., 0, 0], s[..., 2, 0] / s[..., 0, 0]
    d1 = s[..., 1, 1] - l10 * s[..., 1, 0]
    t21 = s[..., 2, 1] - l20 * s[..., 1, 0]
    l21 = t21 / d1
    return LDL3(l10, l20, l21, s[..., 0, 0], d1, s[..., 2, 2] - l20 * s[..., 2, 0] - l21 * t21)


def unit_lower_solve3(f: LDL3, v0, v1, v2) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """The entries of ``L^-1 v`` for the unit lower triangular ``L`` of ``f`` and the
    vectors with entries ``v0, v1, v2`` (each broadcast against ``f``'s), by forward
    substitution."""
    y1 = v1 - f.l10 * v0
    return v0, y1, v2 - f.l20 * v0 - f.l21 * y1
