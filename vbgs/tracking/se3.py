"""Rigid motions: SO(3) and SE(3) exponential and log maps, composition, inverse and
the small-motion Jacobian of a transformed point.

A twist ``xi [..., 6]`` is ``(v, w)``: translation part first, then the rotation
vector (axis times angle, radians). ``T = se3_exp(xi)`` is a ``[..., 4, 4]`` rigid
transform; poses are camera-to-world (:mod:`vbgs.render.camera`), and the tracker
perturbs them on the right, ``T exp(xi)`` (a motion in the camera's own frame).

Every function takes NumPy or JAX arrays and answers in the same kind (NumPy float64
in, float64 out: the trajectory metrics and the drift run on the host in float64; JAX
float32 in the tracker's compiled step). Precision, per kernel:

* the coefficients ``sin t / t``, ``(1 - cos t) / t^2``, ``(t - sin t) / t^3`` and
  ``(1 - (t/2) cot(t/2)) / t^2`` lose every digit to cancellation in float32 at small
  angles when written directly; below :data:`SMALL_ANGLE` they are their Taylor series
  (error under 1e-7 relative there), above it the closed forms (cancellation error
  under 3e-6 relative in float32). ``(1 - cos t)`` is written ``2 sin^2(t/2)``: exact
  at every angle;
* the angle of a rotation is ``atan2(|vee(R - R^T)| / 2, (tr R - 1) / 2)``, not
  ``arccos``, which in float32 cannot resolve angles under about 3e-4 rad;
* near ``t = pi`` the antisymmetric part vanishes and the axis is read from the
  symmetric part instead (:func:`so3_log`); float32 keeps about 1e-3 rad there.
"""

from __future__ import annotations

import numpy as np

# Below this angle (radians) the cancelling coefficients use their Taylor series: in
# float32 (the Taylor error at 0.5 rad is under 1e-9 relative) and in float64 (the
# closed forms' cancellation error at 0.01 rad is under 1e-11 relative).
SMALL_ANGLE = {np.dtype(np.float32): 0.5, np.dtype(np.float64): 0.01}
# Above this angle (radians) so3_log reads the axis from the symmetric part of R.
NEAR_PI = 2.5


def _xp(x):
    """The array module of ``x``: jax.numpy for JAX arrays and tracers, else NumPy."""
    if isinstance(x, np.ndarray) or np.isscalar(x):
        return np
    import jax.numpy as jnp

    return jnp


def _mm(a, b):
    """``a @ b``; for JAX arrays at full float32 precision (:mod:`vbgs.inference.precision`):
    a GPU's default TF32 would round a pose's entries to 10 bits (5e-4 relative: half a
    millimetre at a metre), which composed frame after frame is the tracker's error."""
    if _xp(a) is np and _xp(b) is np:
        return a @ b
    from vbgs.inference.precision import matmul

    return matmul(a, b)


def hat(w):
    """``[w]_x [..., 3, 3]``: the cross-product matrix, ``hat(w) @ p = w x p``."""
    xp = _xp(w)
    z = xp.zeros_like(w[..., 0])
    return xp.stack([xp.stack([z, -w[..., 2], w[..., 1]], -1),
                     xp.stack([w[..., 2], z, -w[..., 0]], -1),
                     xp.stack([-w[..., 1], w[..., 0], z], -1)], -2)


def vee(m):
    """The vector of the antisymmetric part of ``m [..., 3, 3]``: ``vee(hat(w)) = w``."""
    xp = _xp(m)
    return 0.5 * xp.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0],
                           m[..., 1, 0] - m[..., 0, 1]], -1)


def _small(theta):
    """The Taylor threshold for the dtype of ``theta``."""
    return SMALL_ANGLE.get(np.dtype(theta.dtype), SMALL_ANGLE[np.dtype(np.float32)])


def _coefficients(theta):
    """``A = sin t / t``, ``B = (1 - cos t) / t^2``, ``C = (t - sin t) / t^3``, stable
    at every angle (module docstring)."""
    xp = _xp(theta)
    t2 = theta * theta
    small = theta < _small(theta)
    safe = xp.where(small, 1.0, theta)  # the closed forms, never at t -> 0
    half = xp.sin(0.5 * safe) / (0.5 * safe)
    a = xp.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0 - t2**3 / 5040.0, xp.sin(safe) / safe)
    b = xp.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0 - t2**3 / 40320.0, 0.5 * half * half)
    c = xp.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0 - t2**3 / 362880.0,
                 (safe - xp.sin(safe)) / safe**3)
    return a, b, c


def _norm(w):
    xp = _xp(w)
    return xp.sqrt(xp.sum(w * w, -1))


def so3_exp(w):
    """Rotation ``[..., 3, 3]`` of the rotation vector ``w [..., 3]`` (Rodrigues)."""
    xp = _xp(w)
    a, b, _ = _coefficients(_norm(w))
    k = hat(w)
    eye = xp.eye(3, dtype=k.dtype)
    return eye + a[..., None, None] * k + b[..., None, None] * _mm(k, k)


def rotation_angle(rot):
    """The angle ``[...]`` (radians, in [0, pi]) of rotations ``[..., 3, 3]``."""
    xp = _xp(rot)
    cos = 0.5 * (rot[..., 0, 0] + rot[..., 1, 1] + rot[..., 2, 2] - 1.0)
    return xp.arctan2(_norm(vee(rot)), cos)


def so3_log(rot):
    """The rotation vector ``[..., 3]`` of rotations ``[..., 3, 3]`` (angle in [0, pi])."""
    xp = _xp(rot)
    theta = rotation_angle(rot)
    s = vee(rot)  # sin(t) * axis
    a, _, _ = _coefficients(theta)
    near = theta > NEAR_PI
    usual = s / xp.where(near, 1.0, a)[..., None]
    # near pi: (R + R^T) / 2 - cos t I = (1 - cos t) axis axis^T; the column of the
    # largest diagonal entry is the best-conditioned multiple of the axis
    cos = xp.cos(theta)
    sym = 0.5 * (rot + xp.swapaxes(rot, -1, -2)) - cos[..., None, None] * xp.eye(3, dtype=rot.dtype)
    j = xp.argmax(xp.stack([sym[..., 0, 0], sym[..., 1, 1], sym[..., 2, 2]], -1), -1)
    pick = xp.broadcast_to(j[..., None, None], sym.shape[:-1] + (1,))
    col = xp.take_along_axis(sym, pick, -1)[..., 0]  # sym[..., :, j]
    axis = col / xp.maximum(_norm(col), 1e-30)[..., None]
    sign = xp.where(xp.sum(axis * s, -1) < 0, -1.0, 1.0)
    return xp.where(near[..., None], (sign * theta)[..., None] * axis, usual)


def _v_matrix(w):
    """The left Jacobian of SO(3), ``V = I + B [w]_x + C [w]_x^2``: the translation
    of ``se3_exp((v, w))`` is ``V v``."""
    xp = _xp(w)
    _, b, c = _coefficients(_norm(w))
    k = hat(w)
    return xp.eye(3, dtype=k.dtype) + b[..., None, None] * k + c[..., None, None] * _mm(k, k)


def _v_inverse(w):
    """``V^-1 = I - [w]_x / 2 + D [w]_x^2``, ``D = (1 - (t/2) cot(t/2)) / t^2``."""
    xp = _xp(w)
    theta = _norm(w)
    small = theta < _small(theta)
    safe = xp.where(small, 1.0, theta)
    t2 = theta * theta
    d = xp.where(small, 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0 + t2**3 / 1209600.0,
                 (1.0 - 0.5 * safe / xp.tan(0.5 * safe)) / (safe * safe))
    k = hat(w)
    return xp.eye(3, dtype=k.dtype) - 0.5 * k + d[..., None, None] * _mm(k, k)


def from_rt(rot, t):
    """The ``[..., 4, 4]`` transform of rotations ``[..., 3, 3]`` and translations ``[..., 3]``."""
    xp = _xp(rot)
    top = xp.concatenate([rot, t[..., :, None]], -1)
    bottom = xp.broadcast_to(xp.asarray([0.0, 0.0, 0.0, 1.0], dtype=rot.dtype),
                             top.shape[:-2] + (1, 4))
    return xp.concatenate([top, bottom], -2)


def se3_exp(xi):
    """The rigid transform ``[..., 4, 4]`` of twists ``xi = (v, w) [..., 6]``."""
    v, w = xi[..., :3], xi[..., 3:]
    t = _mm(_v_matrix(w), v[..., :, None])[..., 0]
    return from_rt(so3_exp(w), t)


def se3_log(pose):
    """The twist ``(v, w) [..., 6]`` of rigid transforms ``[..., 4, 4]`` (its inverse of
    :func:`se3_exp` for rotation angles under pi)."""
    xp = _xp(pose)
    w = so3_log(pose[..., :3, :3])
    v = _mm(_v_inverse(w), pose[..., :3, 3:4])[..., 0]
    return xp.concatenate([v, w], -1)


def inverse(pose):
    """``T^-1`` of rigid transforms ``[..., 4, 4]`` (transpose, no matrix inversion)."""
    xp = _xp(pose)
    rt = xp.swapaxes(pose[..., :3, :3], -1, -2)
    return from_rt(rt, -_mm(rt, pose[..., :3, 3:4])[..., 0])


def orthonormalise(pose):
    """The rigid transform nearest ``pose [..., 4, 4]``: its rotation block replaced by
    the nearest rotation (Frobenius: ``U V^T`` of its SVD, det +1), the last row
    ``(0, 0, 0, 1)``. Products of float32 transforms drift off SO(3) by ~1e-7 each;
    composed frame after frame (a constant-velocity guess multiplies three) the drift
    grows, and :func:`inverse` (a transpose) is only right for a rotation."""
    xp = _xp(pose)
    u, _, vt = xp.linalg.svd(pose[..., :3, :3])
    det = xp.linalg.det(_mm(u, vt))
    flip = xp.stack([xp.ones_like(det), xp.ones_like(det), det], -1)
    return from_rt(_mm(u * flip[..., None, :], vt), pose[..., :3, 3])


def compose(a, b):
    """``a b``: the transform applying ``b`` first, then ``a``."""
    return _mm(a, b)


def relative(a, b):
    """``a^-1 b``: ``b`` seen from ``a`` (the motion from pose ``a`` to pose ``b``)."""
    return compose(inverse(a), b)


def point_jacobian(p):
    """``d (exp(xi) p) / d xi`` at ``xi = 0``, ``[..., 3, 6]`` for points ``p [..., 3]``:
    ``[I, -[p]_x]``. A pose perturbed on the right, ``T exp(xi)``, moves the world
    point of camera point ``p`` by ``R [I, -[p]_x] xi`` to first order."""
    xp = _xp(p)
    eye = xp.broadcast_to(xp.eye(3, dtype=p.dtype), p.shape[:-1] + (3, 3))
    return xp.concatenate([eye, -hat(p)], -1)
