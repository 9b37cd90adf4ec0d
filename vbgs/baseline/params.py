"""Trainable parameters of the gradient splatting baseline, at a fixed capacity.

Splat k (of a fixed capacity K rows) in d = 2 or 3 dimensions is stored unconstrained:

* ``means [K, d]``: position (world units for scenes, pixels for images);
* ``log_scales [K, d]``: ``s = exp(log_scales)``, the per-axis standard deviations;
* ``rotations``: ``[K, 4]`` quaternions (w, x, y, z; normalised when used) for d = 3,
  ``[K, 1]`` angles θ (radians) for d = 2; ``Σ = R diag(s²) Rᵀ``;
* ``opacity_logits [K]``: ``o = sigmoid(opacity_logits)``;
* ``colour_logits [K, 3]``: ``c = sigmoid(colour_logits)``, so colours always lie in
  (0, 1) and, unlike a clipped raw colour, never get stuck with a zero gradient.
  (3DGS stores a degree-0 SH coefficient ``f`` with ``c = 0.5 + SH_C0 f``; at mid-grey
  its Adam step of 2.5e-3 moves c by ``SH_C0 · 2.5e-3 ≈ 7e-4`` and ours by
  ``sigmoid' · 2.5e-3 = 6e-4``, so the 3DGS feature learning rate carries over.)
* ``active [K]`` bool: rows in use. Inactive rows render with opacity 0 and are free
  slots for densification; the array shapes, hence the compiled step, never change.

``active`` is not trained: the optimiser sees :func:`trainable` (``active=None``,
an empty pytree node, so every tree_map skips it).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference import expfam
from vbgs.inference.precision import matmul
from vbgs.render.splats import (
    Splats,
    covs_from_scale_rotation,
    rotations_from_quaternions,
    scale_rotation_from_covs,
)

INIT_OPACITY = 0.1  # 3DGS's initial opacity
COLOUR_EPS = 1e-3  # initial colours are clipped to [eps, 1 - eps] before the logit
IDENTITY_QUATERNION = (1.0, 0.0, 0.0, 0.0)  # (w, x, y, z)
# Splat colours and opacities are clipped to [eps, 1 - eps] before the logit: far enough
# from 0 and 1 that the logit is finite in float32, close enough that the round trip
# (sigmoid of the logit) renders the same picture to ~1e-6.
SPLAT_EPS = 1e-6


class Params(NamedTuple):
    """K splats' unconstrained parameters (rows) plus the ``active`` mask."""

    means: jax.Array  # [K, d]
    log_scales: jax.Array  # [K, d]
    rotations: jax.Array  # [K, 4] quaternions (d = 3) or [K, 1] angles (d = 2)
    opacity_logits: jax.Array  # [K]
    colour_logits: jax.Array  # [K, 3]
    active: jax.Array | None  # [K] bool; None in the trainable view

    @property
    def capacity(self) -> int:
        return int(self.means.shape[0])

    @property
    def dim(self) -> int:
        return int(self.means.shape[1])


def trainable(params: Params) -> Params:
    """The optimised view: ``params`` with ``active=None`` (skipped by tree maps)."""
    return params._replace(active=None)


def logit(p):
    """``log(p / (1 - p))``, the inverse of ``sigmoid``."""
    return jnp.log(p) - jnp.log1p(-p)


def opacities(params: Params) -> jax.Array:
    """``o = sigmoid(opacity_logits)`` on active rows, 0 elsewhere, ``[K]``."""
    return jnp.where(params.active, jax.nn.sigmoid(params.opacity_logits), 0.0)


def colours(params: Params) -> jax.Array:
    """``c = sigmoid(colour_logits)``, ``[K, 3]`` in (0, 1)."""
    return jax.nn.sigmoid(params.colour_logits)


def rotations_2d(angles: jax.Array) -> jax.Array:
    """``R(θ) = [[cos θ, -sin θ], [sin θ, cos θ]]`` from angles ``[K, 1]``, ``[K, 2, 2]``."""
    c, s = jnp.cos(angles[:, 0]), jnp.sin(angles[:, 0])
    return jnp.stack([jnp.stack([c, -s], -1), jnp.stack([s, c], -1)], -2)


def rotation_matrices(params: Params) -> jax.Array:
    """``R [K, d, d]`` from the quaternions (d = 3) or angles (d = 2)."""
    if params.dim == 3:
        return rotations_from_quaternions(params.rotations)
    return rotations_2d(params.rotations)


def covariances(params: Params) -> jax.Array:
    """``Σ = R diag(s²) Rᵀ`` with ``s = exp(log_scales)``, ``[K, d, d]`` (full float32 products)."""
    scales = jnp.exp(params.log_scales)
    if params.dim == 3:
        return covs_from_scale_rotation(scales, params.rotations)
    rot = rotations_2d(params.rotations)
    return matmul(rot * (scales**2)[:, None, :], jnp.swapaxes(rot, -1, -2))


def to_splats(params: Params) -> Splats:
    """3-D params as :class:`vbgs.render.splats.Splats` (inactive rows at opacity 0). Differentiable."""
    if params.dim != 3:
        raise ValueError(f"Splats are 3-D; these params are {params.dim}-D")
    return Splats(params.means, covariances(params), colours(params), opacities(params))


def init_params(
    means,
    colours,
    scales,
    *,
    capacity: int | None = None,
    active=None,
    opacity: float = INIT_OPACITY,
) -> Params:
    """Params for ``n`` splats at ``means [n, d]`` with ``colours [n, 3]`` in [0, 1] and
    standard deviations ``scales``: one for all (scalar), isotropic ``[n]`` or per axis
    ``[n, d]``.

    capacity: rows K >= n (default n); rows past n are copies of row 0 marked
    inactive. active: ``[n]`` bool (default all True). Rotations start at the identity.
    """
    means = jnp.asarray(means, jnp.float32)
    n, d = means.shape
    if d not in (2, 3):
        raise ValueError(f"means must be [n, 2] or [n, 3], got {means.shape}")
    capacity = n if capacity is None else int(capacity)
    if capacity < n:
        raise ValueError(f"capacity {capacity} is smaller than the {n} splats given")
    scales = jnp.asarray(scales, jnp.float32)
    scales = jnp.broadcast_to(scales[:, None] if scales.ndim == 1 else scales, (n, d))
    cols = jnp.clip(jnp.asarray(colours, jnp.float32), COLOUR_EPS, 1.0 - COLOUR_EPS)
    if cols.shape != (n, 3):
        raise ValueError(f"colours must be [{n}, 3], got {cols.shape}")
    active = jnp.ones(n, bool) if active is None else jnp.asarray(active, bool)
    if active.shape != (n,):
        raise ValueError(f"active must be [{n}] bool, got shape {active.shape}")
    rot = (jnp.broadcast_to(jnp.asarray(IDENTITY_QUATERNION, jnp.float32), (n, 4)) if d == 3
           else jnp.zeros((n, 1), jnp.float32))

    def pad(x):  # [n, ...] -> [capacity, ...], extra rows copy row 0
        return jnp.concatenate([x, jnp.repeat(x[:1], capacity - n, axis=0)])

    return Params(
        means=pad(means),
        log_scales=pad(jnp.log(scales)),
        rotations=pad(rot),
        opacity_logits=jnp.full(capacity, logit(jnp.float32(opacity))),
        colour_logits=pad(logit(cols)),
        active=jnp.concatenate([active, jnp.zeros(capacity - n, bool)]),
    )


def place(params: Params, rows, means, colours, scales, *,
          opacity: float = INIT_OPACITY) -> Params:
    """Fresh isotropic splats in ``rows [m]`` (indices): at ``means [m, d]`` with
    ``colours [m, 3]`` in [0, 1], standard deviation ``scales`` (scalar or ``[m]``),
    identity rotation, opacity ``opacity``; the rows become active. Built on the host
    (m changes from call to call; a device scatter would compile once per m)."""
    rows = np.asarray(rows, np.int64)
    fresh = init_params(means, colours, np.broadcast_to(np.asarray(scales, np.float32),
                                                        (len(rows),)), opacity=opacity)

    def put(a, b):
        out = np.array(a)
        out[rows] = np.asarray(b)
        return jnp.asarray(out)

    return Params(*(put(a, b) for a, b in zip(params, fresh, strict=True)))


def params_from_prior(prior, *, capacity: int | None = None, active=None,
                      opacity: float = INIT_OPACITY) -> Params:
    """Params starting where VBGS starts: a :func:`vbgs.inference.model.init` prior's component means
    (``space.mean + origin``), colour means, and per-axis sigma ``sqrt(diag E[Σ])`` of the
    prior's expected covariance (isotropic for the default prior)."""
    cov = expfam.niw_expected_covariance(prior.space)  # [n, d, d]
    scales = jnp.sqrt(jnp.diagonal(cov, axis1=-2, axis2=-1))  # [n, d]
    return init_params(prior.space.mean + prior.origin, prior.colour.mean, scales,
                       capacity=capacity, active=active, opacity=opacity)


def params_from_splats(splats: Splats, *, eps: float = SPLAT_EPS) -> Params:
    """The parameters of ``splats`` (every row active): means as they are, per-axis sigmas
    and rotations from an eigendecomposition of the covariances
    (:func:`vbgs.render.splats.scale_rotation_from_covs`), colours and opacities through
    the logit after clipping to ``[eps, 1 - eps]``."""
    scales, quats = scale_rotation_from_covs(np.asarray(splats.covs, np.float64))
    clip = lambda a: jnp.clip(jnp.asarray(a, jnp.float32), eps, 1.0 - eps)  # noqa: E731
    return Params(jnp.asarray(splats.means, jnp.float32),
                  jnp.asarray(np.log(scales), jnp.float32), jnp.asarray(quats, jnp.float32),
                  logit(clip(splats.opacities)), logit(clip(splats.colours)),
                  jnp.ones(splats.count, bool))


def live(params: Params, threshold: float) -> jax.Array:
    """Active rows with opacity at least ``threshold``, ``[K]`` bool."""
    return params.active & (jax.nn.sigmoid(params.opacity_logits) >= threshold)


def count_live(params: Params, threshold: float) -> int:
    """Number of :func:`live` rows (host int)."""
    return int(np.asarray(live(params, threshold)).sum())
