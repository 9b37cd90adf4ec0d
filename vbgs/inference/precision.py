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


# Cyclic Jacobi sweeps of :func:`eigh3`: each rotation zeroes one off-diagonal entry and
# the sweeps converge quadratically; on the test's matrices (sizes 1e-12 to 1e12, down to
# a millionth as thick as wide) two fall short of float32's rounding, three reach it, a
# fourth is the margin.
JACOBI_SWEEPS = 4


def eigh3(a00, a01, a02, a11, a12, a22, sweeps: int = JACOBI_SWEEPS):
    """The eigen-decomposition of symmetric 3x3 matrices given by their six entries
    (each ``[...]``, JAX), elementwise: eigenvalues ``[..., 3]`` ascending and the
    eigenvectors as the columns of ``[..., 3, 3]``, by cyclic Jacobi rotations.

    Why: XLA's batched ``eigh`` calls LAPACK per matrix on the CPU, 0.6 us a 3x3 matrix
    (growth fits some 20 thousand patches a 640 x 480 frame), where these rotations over
    arrays of entries take 0.09 us, and on a GPU they are plain elementwise work.
    Precision: float32 suffices. Jacobi's rotations are orthogonal to float32's rounding
    and find the eigenvalues to about ``eps`` times the largest, so the eigenvector of
    the smallest (a patch's normal) is as accurate as the float32 matrix allows, within
    about ``eps * largest / gap`` rad of float64 LAPACK's, ``gap`` the distance to the
    next eigenvalue (``tests/vbgs/inference/test_precision.py``; in the median closer
    than XLA's own float32 ``eigh``). The signs of the vectors are arbitrary, as
    LAPACK's are."""
    one, zero = jnp.ones_like(a00), jnp.zeros_like(a00)
    a = {(0, 0): a00, (0, 1): a01, (0, 2): a02, (1, 1): a11, (1, 2): a12, (2, 2): a22}
    v = {(i, j): one if i == j else zero for i in range(3) for j in range(3)}

    def at(i, j):
        return a[min(i, j), max(i, j)]

    for _ in range(sweeps):
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq, app, aqq = at(p, q), at(p, p), at(q, q)
            off = apq != 0
            theta = (aqq - app) / jnp.where(off, 2.0 * apq, 1.0)
            # the smaller root of t^2 + 2 theta t - 1 = 0, tan of the rotation's angle
            t = jnp.where(theta >= 0, 1.0, -1.0) / (jnp.abs(theta) + jnp.hypot(theta, 1.0))
            t = jnp.where(off, t, 0.0)
            c = 1.0 / jnp.sqrt(t * t + 1.0)
            s = t * c
            r = 3 - p - q
            arp, arq = at(r, p), at(r, q)
            a[min(r, p), max(r, p)] = c * arp - s * arq
            a[min(r, q), max(r, q)] = s * arp + c * arq
            a[p, p], a[q, q], a[p, q] = app - t * apq, aqq + t * apq, zero
            for i in range(3):
                vip, viq = v[i, p], v[i, q]
                v[i, p], v[i, q] = c * vip - s * viq, s * vip + c * viq
    values = [a[0, 0], a[1, 1], a[2, 2]]
    columns = [[v[i, j] for i in range(3)] for j in range(3)]
    for i, j in ((0, 1), (1, 2), (0, 1)):  # a sorting network: ascending
        swap = values[i] > values[j]
        values[i], values[j] = (jnp.where(swap, values[j], values[i]),
                                jnp.where(swap, values[i], values[j]))
        columns[i], columns[j] = (
            [jnp.where(swap, y, x) for x, y in zip(columns[i], columns[j], strict=True)],
            [jnp.where(swap, x, y) for x, y in zip(columns[i], columns[j], strict=True)])
    vectors = jnp.stack([jnp.stack(col, -1) for col in columns], -1)  # [..., 3 rows, 3 cols]
    return jnp.stack(values, -1), vectors


def cholesky_solve(gram: dict, rhs: list) -> list:
    """The solution of ``G c = r`` for symmetric positive definite ``G`` given by its
    entries ``gram[i, j]`` (``i <= j``, each ``[...]``) and ``r`` by its entries
    ``rhs[i]``, elementwise (JAX): ``G = L L^T`` by Cholesky, then forward and back
    substitution. Returns the entries of ``c``.

    Why: XLA's batched ``solve`` runs an LU per matrix on the CPU; these small systems
    (a patch's 6 normal equations, some 20 thousand a frame) cost less as arithmetic
    over arrays of entries. Precision: Cholesky without pivoting is backward stable for
    positive definite ``G``; the caller keeps it so (a ridge, :mod:`vbgs.inference.
    quadric`), else a pivot at or below zero gives inf or nan."""
    p = len(rhs)
    low = {}
    for j in range(p):
        d = gram[j, j] - sum(low[j, k] * low[j, k] for k in range(j))
        low[j, j] = jnp.sqrt(d)
        for i in range(j + 1, p):
            low[i, j] = (gram[j, i] - sum(low[i, k] * low[j, k] for k in range(j))) / low[j, j]
    y = []
    for i in range(p):
        y.append((rhs[i] - sum(low[i, k] * y[k] for k in range(i))) / low[i, i])
    c = [None] * p
    for i in reversed(range(p)):
        c[i] = (y[i] - sum(low[k, i] * c[k] for k in range(i + 1, p))) / low[i, i]
    return c
