"""The Splats type: a set of 3-D Gaussians with colour and opacity, and PLY I/O.

A splat k is the world-space Gaussian ``N(means[k], covs[k])`` carrying a linear
RGB colour ``colours[k]`` in [0, 1] and an opacity ``opacities[k]`` in [0, 1].

Covariances are stored whole. Gradient trainers and the PLY format prefer the
factorisation ``Σ = R diag(s²) Rᵀ`` with per-axis standard deviations ``s`` and a
unit quaternion ``q = (w, x, y, z)`` for the rotation ``R``; the conversions both
ways live here (:func:`covs_from_scale_rotation`, :func:`scale_rotation_from_covs`).

PLY files follow the layout of the original 3DGS code so that common splat viewers
open them: ``x y z``, ``nx ny nz`` (zeros), ``f_dc_0..2`` (colour as the degree-0
spherical-harmonic coefficient), ``opacity`` (logit), ``scale_0..2`` (log sigma)
and ``rot_0..3`` (w x y z).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference.precision import matmul
from vbgs.io_atomic import write_atomic
from vbgs.render.composite import ALPHA_MIN

# Degree-0 real spherical harmonic, 1 / (2 sqrt(pi)): rgb = 0.5 + SH_C0 * f_dc.
SH_C0 = 0.28209479177387814

# Smallest standard deviation written for a covariance axis. Planar or otherwise
# degenerate covariances have zero (or slightly negative, from round-off)
# eigenvalues, whose log would be -inf; they are floored to this sigma instead.
MIN_SCALE = 1e-6

# Opacities are clipped to [OPACITY_EPS, 1 - OPACITY_EPS] before taking the logit
# for PLY, so that fully opaque or transparent splats stay finite.
OPACITY_EPS = 1e-6

_PLY_PROPERTIES = (
    ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity"]
    + [f"scale_{i}" for i in range(3)]
    + [f"rot_{i}" for i in range(4)]
)


class Splats(NamedTuple):
    """k Gaussian splats in world space (a pytree: jit/grad/vmap friendly)."""

    means: jax.Array  # [k, 3] world positions
    covs: jax.Array  # [k, 3, 3] world covariances (symmetric positive semi-definite)
    colours: jax.Array  # [k, 3] linear RGB in [0, 1]
    opacities: jax.Array  # [k] in [0, 1]

    @property
    def count(self) -> int:
        """Number of splats k."""
        return int(self.means.shape[0])


def check_splats(splats: Splats) -> None:
    """Raise ``ValueError`` naming the problem if ``splats`` is malformed.

    Shapes are always checked. Values (NaN/inf) are checked only when the arrays
    are concrete, i.e. not inside a ``jit``/``grad`` trace.
    """
    if not isinstance(splats, Splats):
        raise TypeError(f"expected a vbgs.render.splats.Splats, got {type(splats).__name__}")
    shapes = {name: tuple(np.shape(a)) for name, a in splats._asdict().items()}
    k = shapes["means"][0] if len(shapes["means"]) == 2 else None
    expected = {"means": (k, 3), "covs": (k, 3, 3), "colours": (k, 3), "opacities": (k,)}
    if k is None or any(shapes[name] != exp for name, exp in expected.items()):
        raise ValueError(
            f"malformed Splats: got shapes {shapes}; expected means [k, 3], covs [k, 3, 3], "
            "colours [k, 3] and opacities [k] with the same k"
        )
    for name, a in splats._asdict().items():
        if isinstance(a, jax.core.Tracer):
            continue
        a = np.asarray(a)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"Splats.{name} contains NaN or inf; fix the splats before use")
        if name == "opacities" and a.size and (a.min() < 0 or a.max() > 1):
            raise ValueError(
                f"Splats.opacities must lie in [0, 1], got range [{a.min()}, {a.max()}]"
            )


def prune(splats: Splats, keep_mask: np.ndarray) -> Splats:
    """The splats where ``keep_mask`` (numpy bool ``[k]``) is True, as a smaller Splats."""
    keep_mask = np.asarray(keep_mask)
    if keep_mask.dtype != bool or keep_mask.shape != (splats.count,):
        raise ValueError(
            f"keep_mask must be a boolean array of shape ({splats.count},), "
            f"got dtype {keep_mask.dtype} and shape {keep_mask.shape}"
        )
    (idx,) = np.nonzero(keep_mask)
    return Splats(*(jnp.asarray(a)[idx] for a in splats))


def drawn(splats: Splats) -> Splats:
    """The splats the rasterizer draws (opacity >= :data:`vbgs.render.composite.ALPHA_MIN`):
    the one definition of a "component used" for every method (``components_used``, the
    PLY export)."""
    return prune(splats, np.asarray(splats.opacities) >= ALPHA_MIN)


# --------------------------------------------------------------------------- #
# Covariance <-> (scale, rotation)
# --------------------------------------------------------------------------- #


@jax.jit
def rotations_from_quaternions(quats: jax.Array) -> jax.Array:
    """Rotation matrices ``[k, 3, 3]`` from quaternions ``[k, 4]`` (w, x, y, z).

    The quaternion is normalised first, then
    ``R = I + 2 w [v]x + 2 [v]x²`` with ``v = (x, y, z)``, written out entrywise.
    """
    q = quats / jnp.linalg.norm(quats, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


@jax.jit
def covs_from_scale_rotation(scales: jax.Array, quats: jax.Array) -> jax.Array:
    """World covariances ``Σ = R diag(s²) Rᵀ``, ``[k, 3, 3]``.

    scales: ``[k, 3]`` standard deviations s along the splat's own axes;
    quats: ``[k, 4]`` rotations as (w, x, y, z), normalised here. Differentiable. The
    product runs at full float32 precision (:func:`vbgs.inference.precision.matmul`): in TF32 a thin
    splat's small variances would take the rounding error of the large ones.
    """
    rot = rotations_from_quaternions(quats)  # [k, 3, 3]
    scaled = rot * (scales**2)[..., None, :]  # R diag(s²)
    return matmul(scaled, jnp.swapaxes(rot, -1, -2))


def quaternions_from_rotations(rots: np.ndarray) -> np.ndarray:
    """Unit quaternions ``[k, 4]`` (w, x, y, z, with w >= 0) from proper rotations ``[k, 3, 3]``.

    Shepperd's method: of the four expressions for 4w², 4x², 4y², 4z² in terms of
    the trace and diagonal, use the largest to avoid dividing by a small number.
    """
    r = np.asarray(rots, np.float64)
    d0, d1, d2 = r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]
    # 4 * (w², x², y², z²), each from the diagonal.
    four_sq = np.stack([1 + d0 + d1 + d2, 1 + d0 - d1 - d2, 1 - d0 + d1 - d2, 1 - d0 - d1 + d2], -1)
    best = np.argmax(four_sq, axis=-1)  # [k]
    big = 0.5 * np.sqrt(np.maximum(np.take_along_axis(four_sq, best[:, None], -1)[:, 0], 0.0))
    # Off-diagonal sums/differences: 4wx, 4wy, 4wz, 4xy, 4xz, 4yz.
    wx, wy, wz = r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]
    xy, xz, yz = r[:, 0, 1] + r[:, 1, 0], r[:, 0, 2] + r[:, 2, 0], r[:, 1, 2] + r[:, 2, 1]
    inv = 1.0 / (4.0 * big)
    candidates = np.stack(
        [
            np.stack([big, wx * inv, wy * inv, wz * inv], -1),
            np.stack([wx * inv, big, xy * inv, xz * inv], -1),
            np.stack([wy * inv, xy * inv, big, yz * inv], -1),
            np.stack([wz * inv, xz * inv, yz * inv, big], -1),
        ],
        1,
    )  # [k, 4 candidates, 4]
    q = candidates[np.arange(len(r)), best]
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def scale_rotation_from_covs(
    covs: np.ndarray, min_scale: float = MIN_SCALE
) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis sigmas ``[k, 3]`` and quaternions ``[k, 4]`` (w, x, y, z) with Σ ≈ R diag(s²) Rᵀ.

    Eigendecomposition of the symmetrised covariance: ``s = sqrt(max(λ, min_scale²))``
    (planar/degenerate covariances get the floor instead of a zero or negative
    variance) and R the eigenvectors, with one flipped if needed so ``det R = +1``.
    Computed in float64 with numpy.
    """
    covs = np.asarray(covs, np.float64)
    if covs.ndim != 3 or covs.shape[1:] != (3, 3):
        raise ValueError(f"covs must have shape [k, 3, 3], got {covs.shape}")
    if not np.all(np.isfinite(covs)):
        raise ValueError("covs contains NaN or inf")
    evals, evecs = np.linalg.eigh(0.5 * (covs + np.swapaxes(covs, -1, -2)))  # [k, 3], [k, 3, 3]
    evecs[:, :, 2] *= np.sign(np.linalg.det(evecs))[:, None]  # reflections -> rotations
    scales = np.sqrt(np.maximum(evals, min_scale**2))
    return scales, quaternions_from_rotations(evecs)


# --------------------------------------------------------------------------- #
# PLY (3DGS layout)
# --------------------------------------------------------------------------- #


def save_ply(path, splats: Splats) -> None:
    """Write ``splats`` as a binary little-endian PLY in the 3DGS layout (float32 fields)."""
    from plyfile import PlyData, PlyElement

    check_splats(splats)
    means = np.asarray(splats.means, np.float64)
    scales, quats = scale_rotation_from_covs(np.asarray(splats.covs))
    opac = np.clip(np.asarray(splats.opacities, np.float64), OPACITY_EPS, 1.0 - OPACITY_EPS)
    columns = np.concatenate(
        [
            means,
            np.zeros_like(means),  # normals, unused
            (np.asarray(splats.colours, np.float64) - 0.5) / SH_C0,
            np.log(opac / (1.0 - opac))[:, None],
            np.log(scales),
            quats,
        ],
        axis=1,
    )  # [k, 17]
    vertex = np.empty(len(means), dtype=[(name, "f4") for name in _PLY_PROPERTIES])
    for i, name in enumerate(_PLY_PROPERTIES):
        vertex[name] = columns[:, i]
    ply = PlyData([PlyElement.describe(vertex, "vertex")])
    write_atomic(path, lambda tmp: ply.write(str(tmp)))


def load_ply(path) -> Splats:
    """Read a 3DGS-layout PLY into float32 Splats (extra properties such as ``f_rest_*`` are ignored).

    Colours are ``clip(0.5 + SH_C0 * f_dc, 0, 1)``; opacity is the sigmoid of the
    stored logit; covariances are rebuilt from ``exp(scale)`` and the normalised
    quaternion.
    """
    from plyfile import PlyData

    ply = PlyData.read(str(path))
    if "vertex" not in ply:
        raise ValueError(f"{path}: no 'vertex' element; not a Gaussian-splat PLY")
    vertex = ply["vertex"]
    names = {p.name for p in vertex.properties}
    missing = [n for n in _PLY_PROPERTIES if n not in names and not n.startswith("n")]
    if missing:
        raise ValueError(f"{path}: missing vertex properties {missing} of the 3DGS layout")

    def cols(*keys):
        return np.stack([np.asarray(vertex[key], np.float64) for key in keys], axis=1)

    means = cols("x", "y", "z")
    colours = np.clip(0.5 + SH_C0 * cols("f_dc_0", "f_dc_1", "f_dc_2"), 0.0, 1.0)
    opacities = 1.0 / (1.0 + np.exp(-np.asarray(vertex["opacity"], np.float64)))
    scales = np.exp(cols("scale_0", "scale_1", "scale_2"))
    quats = cols("rot_0", "rot_1", "rot_2", "rot_3")
    if not np.all(np.isfinite(quats)) or np.any(np.linalg.norm(quats, axis=1) == 0):
        raise ValueError(f"{path}: rotations must be finite, non-zero quaternions")
    with jax.enable_x64(True):  # rebuild in float64, store float32
        covs = np.asarray(covs_from_scale_rotation(jnp.asarray(scales), jnp.asarray(quats)))
    splats = Splats(
        *(jnp.asarray(a, jnp.float32) for a in (means, covs, colours, opacities))
    )
    check_splats(splats)
    return splats


# VBGS posteriors become splats with their expected covariance E[Sigma] = Psi / (nu - d - 1),
# scaled by VBGS_COV_SCALE (sigma multiplier), and are drawn with the pixel filter
# VBGS_BLUR: a variance (px²) added to each projected covariance (vbgs.render.raster.rasterize's
# ``blur``). The expected covariance, not the inverse expected precision Psi / nu, because
# it is the posterior mean of what the splat draws (the spread of the points it explains);
# the two differ by (nu - 4) / nu, which the scale absorbs. 3DGS adds 0.3 px² to every
# splat and its optimiser shrinks the splats to make up for it; VBGS covariances are fitted
# to the points, so 0.3 bled past every silhouette (at 0.3, 50k components scored below
# 20k). Rule: the best mean validation PSNR over the object and the room (128 px, 20k,
# 60 frames), `python -m experiments.run tune --scene object room --components 20000
# --frames 60 --size 128 --grid splat_scale=1.0,1.2,1.4 splat_blur=0,0.02,0.05
# --out results/tuning/prior/splat` (results/tuning/prior/splat/mean.md, its command and
# code version in its first line): scale 1.2 the best; blur 0 leads the default 0.02 there
# by about a tenth of a dB but not on the walk nor on the object under the Kinect
# (splat_blur_walk/, splat_blur_kinect/ beside it), and moving it is left for a round that
# re-makes the records. The walk and 50k components: results/tuning/splat_scale/ (the walk
# at 50k wants larger splats, experiments.tasks.scene_report.FEW_POINTS; over the three
# scenes 1.2 is the best mean at 20k, k20000_mean.md; at 50k 1.35 leads it by less than a
# tenth of a dB, k50000_mean.md).
# Opacity comes from evidence (vbgs.render.opacity); VBGS_OPACITY is the constant of the old
# rule (`opacity_rule="constant"`), kept for comparison.
VBGS_OPACITY = 0.5
VBGS_COV_SCALE = 1.2
VBGS_BLUR = 0.02


def mixture_geometry(mixture) -> tuple[jax.Array, jax.Array]:
    """World means ``E[mu_k]`` ``[k, 3]`` and expected covariances ``E[Sigma_k] =
    Psi_k / (nu_k - 4)`` ``[k, 3, 3]`` of a 3-D mixture (prior or posterior)."""
    from vbgs.inference import expfam  # local: splats stays importable without the model

    if mixture.dim != 3:
        raise ValueError(f"splats need a 3-D mixture, got a {mixture.dim}-D one")
    return mixture.space.mean + mixture.origin, expfam.niw_expected_covariance(mixture.space)


def from_posterior(posterior, prior, *, opacity: float = VBGS_OPACITY,
                   cov_scale: float = VBGS_COV_SCALE, min_count: float | None = None,
                   drop_unused: bool = True, opacities=None, colours=None) -> Splats:
    """Splats from a fitted 3-D VBGS mixture (``vbgs.inference.model.Mixture``).

    means: ``E[mu_k]`` in world units; covs: ``cov_scale^2 E[Sigma_k] =
    cov_scale^2 Psi_k / (nu_k - 4)``; colours: per component ``colours [k, 3]`` when
    given (e.g. fitted to the picture, :mod:`vbgs.render.colour_fit`), else ``E[mu_c,k]``,
    clipped to [0, 1];
    opacities: per component ``opacities [k]`` when given (e.g. from evidence,
    :mod:`vbgs.render.opacity`), else the constant ``opacity``. Components that received less
    than ``min_count`` points' worth of data (``alpha_k - alpha0_k``; default
    :data:`vbgs.inference.model.MIN_USED_COUNT`, :func:`vbgs.inference.model.used_components`) never saw the
    scene: they are pruned, or with ``drop_unused=False`` kept with opacity 0 (the
    rasterizer skips them), so that the splat count, and with it the compiled
    renderer, stays the same while a stream is learned.
    """
    means, covs = mixture_geometry(posterior)
    if not (0.0 < opacity <= 1.0) or cov_scale <= 0:
        raise ValueError(f"opacity must be in (0, 1] and cov_scale > 0, got {opacity}, {cov_scale}")
    from vbgs.inference.model import MIN_USED_COUNT, used_components  # local, as mixture_geometry

    used = used_components(posterior.alpha - prior.alpha,
                           MIN_USED_COUNT if min_count is None else min_count)  # [k]
    chosen = opacity if opacities is None else jnp.clip(jnp.asarray(opacities), 0.0, 1.0)
    splats = Splats(
        means=means,
        covs=cov_scale**2 * covs,
        colours=jnp.clip(posterior.colour.mean if colours is None else jnp.asarray(colours),
                         0.0, 1.0),
        opacities=jnp.where(used, chosen, 0.0).astype(posterior.alpha.dtype),
    )
    return prune(splats, np.asarray(used)) if drop_unused else splats
