"""The VBGS mixture: prior, posterior, E-step, M-step, ELBO, batch CAVI and streaming.

A data point has a position ``xyz [d]`` (d = 2 for images, 3 for scenes) and a colour
``rgb [3]``. Component k explains it with
``pi_k N(xyz | mu_k, Sigma_k) N(rgb | mu_c,k, sigma_c^2 I)`` under the conjugate priors
of :mod:`vbgs.inference.expfam`. Because the model is conjugate, a batch changes the posterior
only through summed statistics: ``posterior = m_step(prior, stats)``.

State is immutable: ``state, info = update(state, xyz, rgb)``. Batch CAVI over
:func:`update` lives in :mod:`vbgs.inference.fit`; the stream loop (each batch once, under
a fixed, re-seeded or growing reference) is :func:`vbgs.mapping.update_points`, whose
compiled stepper (:mod:`vbgs.inference.stepper`) :func:`update` is the reference of.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference import area, candidates, expfam, precision
from vbgs.inference.expfam import NIW, ColourNormal, Stats
from vbgs.inference.precision import mat_vec

Assign = Literal["prior", "posterior"]
InitScheme = Literal["random", "data"]
EStep = Literal["dense", "sparse"]


@dataclass(frozen=True)
class PriorConfig:
    """Prior strengths and the colour noise; hyperparameters, not state.

    The spatial scale of the prior is not a constant: it is the length ``ell`` of the
    cell each component would own if the K components tiled the cells the data occupy
    (:func:`vbgs.inference.area.occupied_cell_length`: about ``sqrt(area / K)`` for points on
    surfaces), at most the cell of the data's bounding box,
    ``(prod_i extent_i / K)^(1/d_eff)`` over the non-degenerate dimensions, so the
    defaults work whatever the units, the extent, the data's dimension or K.

    colour_noise: ``sigma_c``, the fixed colour standard deviation of a component (colours
        in [0, 1]); small values make components colour-pure (the paper's "delta").
    cov_scale: prior expected covariance ``E[Sigma] = (cov_scale * ell)^2 I``.
    cov_strength: ``nu_0 - d - 1``; pseudo-points behind the prior covariance.
    mean_strength: ``kappa_0``; pseudo-points behind the prior spatial mean.
    colour_strength: ``lambda_0``; pseudo-points behind the prior colour mean.
    alpha: Dirichlet concentration per component.
    surface_thickness: for components a stream grows on 3-D points (:mod:`vbgs.inference.grow`),
        the prior's standard deviation along the local surface normal relative to the
        one within the surface: ``E[Sigma] = (cov_scale ell)^2 (I - n n^T +
        surface_thickness^2 n n^T)``, ``n`` the normal of the batch's points around the
        component (:func:`vbgs.inference.grow.local_normals`). 1 is the isotropic prior (images,
        oracle starts, and every 2-D model, use it whatever the value).
    """

    colour_noise: float = 0.05
    cov_scale: float = 0.5
    cov_strength: float = 1.0
    mean_strength: float = 1.0
    colour_strength: float = 1.0
    alpha: float = 1.0
    surface_thickness: float = 1.0

    def __post_init__(self):
        for name in ("colour_noise", "cov_scale", "cov_strength", "mean_strength",
                     "colour_strength", "alpha", "surface_thickness"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"PriorConfig.{name} must be a positive finite number, got {value!r}")


# A config is part of a State's structure, not an array: jit sees it as static.
jax.tree_util.register_static(PriorConfig)

# The prior for points on surfaces (RGB-D scenes). An isotropic prior is a ball; on
# surface data its thickness along the normal, (cov_scale ell)^2 / (n + 1) after n points,
# is all the thickness a component has, so components stay blobs until they hold many
# points: with the isotropic prior a median component of the object (128 px, 20k) had its
# smallest sigma at 0.65 of its largest, and fresh ones grown on 1-4 points at 0.81; drawn
# over the silhouettes of views that had seen the surface before, those cost an early view
# 0.5 dB. A component a stream grows on a 3-D batch gets a prior flattened along the
# batch's local surface normal (vbgs.inference.grow.local_normals), thickness 0.1 of its width.
# Images fill their plane: no normal, the isotropic prior. Rule: the best mean validation
# PSNR over the object and the room (128 px, 20k, 60 frames), one axis at a time around the
# defaults, by `python -m experiments.run tune --scene object room --components 20000
# --frames 60 --size 128 --grid prior.NAME=... --out results/tuning/prior/NAME`
# (the command and code version head each table): cov_scale 0.6 the best,
# results/tuning/prior/cov_scale/mean.md; thickness 0.1 the best, well above the isotropic
# prior's thickness 1, results/tuning/prior/surface_thickness/mean.md.
SURFACE_COV_SCALE = 0.6
SURFACE_THICKNESS = 0.1
SURFACE_PRIOR = PriorConfig(cov_scale=SURFACE_COV_SCALE, surface_thickness=SURFACE_THICKNESS)


class Mixture(NamedTuple):
    """Parameters of the whole mixture; the prior and the posterior share this type.

    Spatial quantities live in a frame centred on ``origin`` (world = frame + origin).
    """

    space: NIW
    colour: ColourNormal
    alpha: jnp.ndarray  # [k]
    origin: jnp.ndarray  # [d]

    @property
    def n_components(self) -> int:
        return self.alpha.shape[0]

    @property
    def dim(self) -> int:
        return self.origin.shape[0]


# Points' worth of responsibility ``N_k = sum_n r_nk`` (= ``alpha_k - alpha0_k``) from
# which a component counts as used; below it its weight is still at its prior.
MIN_USED_COUNT = 0.5


def used_components(counts, min_count: float = MIN_USED_COUNT):
    """``used_k = (N_k >= min_count)``, ``[k]`` bool, from counts ``N [k]`` (NumPy or JAX).

    The one "component used" rule: unused components are re-seeded
    (:mod:`vbgs.inference.reassign`), pruned from splats (:func:`vbgs.render.splats.from_posterior`)
    and left out of the "components used" figures.
    """
    return counts >= min_count


class State(NamedTuple):
    """What streaming carries from batch to batch: no data, only summed statistics.

    ``config``: the hyperparameters the state was started with (:func:`start`), static
    under jit; :func:`update` uses them and refuses a different config. None marks an
    unbound state (started without a config, or rebuilt field by field): then each
    :func:`update` call's ``config`` applies, default :class:`PriorConfig`.
    """

    prior: Mixture
    posterior: Mixture
    stats: Stats
    config: PriorConfig | None = None


class Info(NamedTuple):
    """Per-update diagnostics.

    elbo: ELBO of the assignment model on this batch, ``sum_n log sum_k exp(l_nk) - KL``
        (for ``fit`` this is the objective that CAVI never decreases);
    point_loglik: ``log sum_k exp(l_nk)`` per point ``[n]`` (how well each point is explained).
    """

    elbo: jnp.ndarray
    point_loglik: jnp.ndarray


# --------------------------------------------------------------------------- prior


def cell_length(lo: np.ndarray, hi: np.ndarray, n_components: int) -> float:
    """``ell``: side of the cell each of K components would own in the box [lo, hi].

    Dimensions thinner than 1e-3 of the widest are treated as degenerate (planar
    or linear data) and left out; a single point gets ``ell = 1``.
    """
    extent = np.asarray(hi, np.float64) - np.asarray(lo, np.float64)
    widest = float(extent.max(initial=0.0))
    if widest <= 0:
        return 1.0
    live = extent[extent > 1e-3 * widest]
    return float(np.exp(np.log(live).sum() / live.size - np.log(n_components) / live.size))


def make_prior(
    means: jnp.ndarray,
    colours: jnp.ndarray,
    origin: jnp.ndarray,
    ell: float,
    config: PriorConfig = PriorConfig(),
) -> Mixture:
    """A prior with component spatial means ``means [k, d]`` (world) and colour means
    ``colours [k, 3]``, scaled by the cell length ``ell`` (see :class:`PriorConfig`)."""
    k, d = means.shape
    dtype = means.dtype
    ones = jnp.ones((k,), dtype)
    var = (config.cov_scale * ell) ** 2
    scale = jnp.broadcast_to(config.cov_strength * var * jnp.eye(d, dtype=dtype), (k, d, d))
    space = NIW(
        means - origin, config.mean_strength * ones, (d + 1.0 + config.cov_strength) * ones, scale
    )
    colour = ColourNormal(colours.astype(dtype), config.colour_strength * ones)
    return Mixture(space, colour, config.alpha * ones, origin.astype(dtype))


def init(
    xyz,
    rgb,
    n_components: int,
    *,
    key: jax.Array,
    scheme: InitScheme = "random",
    config: PriorConfig = PriorConfig(),
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    length_scale: float | None = None,
) -> Mixture:
    """A prior for ``n_components`` placed on data ``xyz [n, d]``, ``rgb [n, 3]``.

    ``length_scale``: the cell length ``ell`` the prior covariance is scaled by (see
    :class:`PriorConfig`); None estimates it from ``xyz`` (cells the data occupy, at
    most the bounds' box cell).

    ``random``: spatial means uniform in the bounds (the data's box unless ``bounds``
    is given) and colour means the colours of randomly chosen data points (the data's
    own colour distribution, no colour absent from the data; measured better than
    uniform in the data's colour box or one shared mean colour). ``data``: spatial
    and colour means on randomly chosen data points (with replacement only when
    there are more components than points).
    """
    xyz, rgb = check_points(xyz, rgb)
    if not isinstance(n_components, (int, np.integer)) or n_components < 1:
        raise ValueError(f"n_components must be a positive integer, got {n_components!r}")
    if scheme not in ("random", "data"):
        raise ValueError(f"unknown init scheme {scheme!r}: use 'random' or 'data'")
    pts = np.asarray(xyz, np.float64)
    lo, hi = (np.asarray(b, np.float64) for b in bounds) if bounds else (pts.min(0), pts.max(0))
    origin = jnp.asarray(0.5 * (lo + hi), xyz.dtype)
    means, colours = _place(key, xyz, rgb, jnp.asarray(lo, xyz.dtype), jnp.asarray(hi, xyz.dtype),
                            origin, n_components, scheme)
    if length_scale is None:
        length_scale = area.occupied_cell_length(pts, n_components, lo,
                                                 cell_length(lo, hi, n_components))
    return _make_prior(means, colours, origin, length_scale, config)


@partial(jax.jit, static_argnames=("n_components", "scheme"))
def _place(key, xyz, rgb, lo, hi, origin, n_components: int, scheme: str):
    """Component spatial and colour means for :func:`init` (one compiled function)."""
    k_pos, k_col, k_pick = jax.random.split(key, 3)
    dtype = xyz.dtype
    if scheme == "random":
        u = jax.random.uniform(k_pos, (n_components, xyz.shape[1]), dtype)
        # uniform in the box, expressed about the origin to keep precision far from 0
        means = origin + (u - 0.5) * (hi - lo)
        colours = rgb[jax.random.choice(k_col, rgb.shape[0], (n_components,))]
        return means, colours
    n = xyz.shape[0]
    idx = jax.random.choice(k_pick, n, (n_components,), replace=n_components > n)
    return xyz[idx], rgb[idx]


_make_prior = jax.jit(make_prior, static_argnames=("config",))


def check_points(xyz, rgb) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Validate a batch at the library boundary: shapes, dtypes, finiteness."""
    xyz_np, rgb_np = check_points_host(xyz, rgb)
    return jnp.asarray(xyz_np), jnp.asarray(rgb_np)


def check_points_host(xyz, rgb) -> tuple[np.ndarray, np.ndarray]:
    """:func:`check_points` on the host: numpy arrays of one floating dtype."""
    xyz_np, rgb_np = np.asarray(xyz), np.asarray(rgb)
    if xyz_np.ndim != 2 or xyz_np.shape[1] not in (2, 3):
        raise ValueError(f"positions must have shape [n, 2] or [n, 3], got {xyz_np.shape}")
    if rgb_np.shape != (xyz_np.shape[0], 3):
        raise ValueError(
            f"colours must have shape [n, 3] matching {xyz_np.shape[0]} positions, got {rgb_np.shape}"
        )
    if xyz_np.shape[0] == 0:
        raise ValueError("no points: the batch is empty")
    for name, a in (("positions", xyz_np), ("colours", rgb_np)):
        if not np.issubdtype(a.dtype, np.floating):
            raise TypeError(f"{name} must be floating point, got dtype {a.dtype}")
        if not np.isfinite(a).all():
            raise ValueError(f"{name} contain NaN or inf ({np.size(a) - np.isfinite(a).sum()} values)")
    dtype = np.dtype(jnp.result_type(xyz_np.dtype, rgb_np.dtype))
    return xyz_np.astype(dtype, copy=False), rgb_np.astype(dtype, copy=False)


def padded_batch(xyz, rgb, origin, size: int, dtype) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A validated batch, centred on ``origin`` and padded to ``size`` rows on the host:
    ``(x [size, d], c [size, 3], w [size])`` with weight 0 on padding. Done in numpy so
    that a new point count costs no compilation (eager JAX ops compile per shape)."""
    xyz, rgb = check_points_host(xyz, rgb)
    n, d = xyz.shape
    dtype = np.dtype(dtype)
    x, c, w = np.zeros((size, d), dtype), np.zeros((size, 3), dtype), np.zeros((size,), dtype)
    x[:n] = xyz - np.asarray(origin, np.float64).astype(xyz.dtype)
    c[:n], w[:n] = rgb, 1.0
    return x, c, w


def padded_rays(ray, n: int, size: int, dtype) -> np.ndarray | None:
    """Per-point noise along the rays ``ray [n, d]`` padded to ``size`` rows (zeros:
    padding has weight 0 anyway); None stays None (exact data)."""
    if ray is None:
        return None
    ray = np.asarray(ray)
    if ray.ndim != 2 or ray.shape[0] != n or not np.isfinite(ray).all():
        raise ValueError(f"ray must be finite [n={n}, d] noise vectors, got shape {ray.shape}")
    out = np.zeros((size, ray.shape[1]), dtype)
    out[:n] = ray
    return out


# --------------------------------------------------------------------------- E-step

# Points per chunk are chosen so a chunk's [chunk, k] log-likelihood block holds about
# this many entries (4 MB in float32, cache-sized: measured fastest on CPU); memory
# stays bounded whatever n and k.
_BLOCK_ENTRIES = 1 << 20


def chunk_size(n: int, k: int) -> int:
    """Points per E-step chunk: the largest power of two dividing ``n`` that keeps a
    ``[chunk, k]`` block near ``_BLOCK_ENTRIES``."""
    target = max(64, _BLOCK_ENTRIES // max(k, 1))
    return math.gcd(1 << (target.bit_length() - 1), n)


def bucket_size(n: int) -> int:
    """Padded batch size: ``n`` rounded up to a multiple of an eighth of its power of
    two, so frames with slightly different point counts share one compiled E-step
    (at most 8 sizes per octave, under 12.5% wasted work)."""
    step = max(1, 1 << max(0, (n - 1).bit_length() - 3))
    return -(-n // step) * step


def features(x: jnp.ndarray, c: jnp.ndarray | None) -> jnp.ndarray:
    """``phi = [vec(x x^T), x, c, 1]`` per point, ``[n, d*d + d (+ 3) + 1]``.

    ``x [n, d]`` positions (about the mixture's origin), ``c [n, 3]`` colours or None.
    The log-joint of point n under component k is linear in these features,
    ``l_nk = phi_n . w_k - |c_n|^2 / (2 sigma_c^2)`` with ``w_k`` from
    :func:`log_joint_weights` (the colour-norm term is the same for every k), and the
    sufficient statistics are their responsibility-weighted sums
    ``sum_n r_nk phi_n`` (:func:`moments_to_stats`).
    """
    parts = [(x[:, :, None] * x[:, None, :]).reshape(x.shape[0], -1), x]
    if c is not None:
        parts.append(c)
    parts.append(jnp.ones((x.shape[0], 1), x.dtype))
    return jnp.concatenate(parts, -1)


class Terms(NamedTuple):
    """Per-component terms of the log-joint in centred form:
    ``l_nk = const_k - 1/2 (x_n - m_k)^T P_k (x_n - m_k) - |c_n - mc_k|^2 / (2 sigma_c^2)``
    with ``P_k = E[Sigma_k^-1]`` and ``const_k = E[log pi_k] + 1/2 E[log|Sigma_k^-1|]
    - d/2 log 2pi - d/(2 kappa_k) - 3/2 log(2 pi sigma_c^2) - 3/(2 lambda_k)``.

    Depends on the assigning model only, so under prior assignment it is built once per
    stream. ``colour_mean`` is None when the colour is left out (see
    :func:`log_joint_weights`).
    """

    mean: jnp.ndarray  # [k, d]
    prec: jnp.ndarray  # [k, d, d]
    colour_mean: jnp.ndarray | None  # [k, 3]
    const: jnp.ndarray  # [k]


def component_terms(q: Mixture, colour_noise: float | None,
                    alpha_total: jnp.ndarray | None = None,
                    logdet_scale: jnp.ndarray | None = None) -> Terms:
    """The centred-form terms of :class:`Terms` for the assigning model ``q``;
    ``alpha_total``: ``sum_k alpha_k`` of the whole mixture when ``q`` holds only some of
    its rows (``E[log pi_k]`` needs it; default ``q.alpha.sum()``); ``logdet_scale``:
    ``log |Psi_k|`` when the caller has it
    (:func:`vbgs.inference.expfam.niw_expected_logdet_precision`)."""
    prec = expfam.niw_expected_precision(q.space)
    const = expfam.niw_centred_loglik_constant(q.space, logdet_scale)  # about its own mean
    const = const + expfam.dirichlet_expected_log(q.alpha, alpha_total)
    colour_mean = None
    if colour_noise is not None:
        _, c_const = expfam.colour_loglik_coefficients(
            q.colour._replace(mean=jnp.zeros_like(q.colour.mean)), colour_noise)
        const, colour_mean = const + c_const, q.colour.mean
    return Terms(q.space.mean, prec, colour_mean, const)


def log_joint_weights(q: Mixture, colour_noise: float | None,
                      alpha_total: jnp.ndarray | None = None) -> jnp.ndarray:
    """``W [k, F]`` with ``l_nk = phi_n . W_k - |c_n|^2 / (2 sigma_c^2)`` where
    ``l_nk = E[log pi_k] + E[log N(x_n|mu_k,Sigma_k)] (+ E[log N(c_n|mu_c,k, sigma_c^2)])``:
    the centred form of :class:`Terms` expanded into features, ``W_k = [-1/2 vec(P_k),
    P_k m_k, mc_k / sigma_c^2, const_k - 1/2 m_k^T P_k m_k - |mc_k|^2 / (2 sigma_c^2)]``.

    The feature form cancels large terms, so products with it must run at full float32
    precision (:func:`feature_logits`). With ``colour_noise=None`` the colour term is
    left out (responsibilities given the position only, as the image renderer needs).
    ``alpha_total`` as in :func:`component_terms`.
    """
    t = component_terms(q, colour_noise, alpha_total)
    k = t.prec.shape[0]
    pm = mat_vec(t.prec, t.mean)  # [k, d]
    const = t.const - 0.5 * jnp.sum(t.mean * pm, -1)
    cols = [-0.5 * t.prec.reshape(k, -1), pm]
    if colour_noise is not None:
        cols.append(t.colour_mean / colour_noise**2)
        const = const - 0.5 * jnp.sum(t.colour_mean**2, -1) / colour_noise**2
    cols.append(const[:, None])
    return jnp.concatenate(cols, -1)


def feature_logits(phi: jnp.ndarray, weights: jnp.ndarray) -> jnp.ndarray:
    """``phi [n, F] @ W^T [F, k]`` at full float32 precision (explicit: the feature form
    cancels terms much larger than the result, see :mod:`vbgs.inference.precision`)."""
    return precision.matmul(phi, weights.T)


def moments_to_stats(acc: jnp.ndarray, d: int) -> Stats:
    """Split summed ``r_nk phi_n`` rows ``[k, F]`` (see :func:`features`) into Stats;
    rows ``[k, F + d*d + d]`` carry the latent moments of measured points last,
    ``sum_noise`` then ``sum_shift`` (see :func:`e_step_with`)."""
    k = acc.shape[0]
    width = d * d + d + 4
    return Stats(
        count=acc[:, width - 1],
        sum_x=acc[:, d * d : d * d + d],
        sum_xx=acc[:, : d * d].reshape(k, d, d),
        sum_c=acc[:, d * d + d : d * d + d + 3],
        sum_noise=acc[:, width:width + d * d].reshape(k, d, d) if acc.shape[1] > width
        else None,
        sum_shift=acc[:, width + d * d:] if acc.shape[1] > width else None,
    )


def e_step(q: Mixture, x: jnp.ndarray, c: jnp.ndarray, w: jnp.ndarray, colour_noise: float,
           chunk: int, cand: jnp.ndarray | None = None,
           ray: jnp.ndarray | None = None) -> tuple[Stats, jnp.ndarray]:
    """E-step under ``q`` on centred points ``x [n, d]``, colours ``c [n, 3]`` and
    point weights ``w [n]`` (0 for padding); n must be a multiple of ``chunk``.

    ``r_nk = softmax_k l_nk`` in log space, chunk by chunk, over all components
    (dense) or over each point's candidates ``cand [n, C]`` (sparse, see
    :mod:`vbgs.inference.candidates`). Returns the summed statistics and
    ``log sum_k exp(l_nk)`` per point; ``ray`` as in :func:`e_step_with`.
    """
    reference = log_joint_weights(q, colour_noise) if cand is None else component_terms(
        q, colour_noise)
    return e_step_with(reference, x, c, w, colour_noise, chunk, cand, ray)


def e_step_with(reference, x: jnp.ndarray, c: jnp.ndarray, w: jnp.ndarray,
                colour_noise: float, chunk: int, cand: jnp.ndarray | None = None,
                ray: jnp.ndarray | None = None, partial_lists: bool = False,
                n_valid: jnp.ndarray | None = None) -> tuple[Stats, jnp.ndarray]:
    """:func:`e_step` given the assigning model's precomputed terms: feature weights
    ``[k, F]`` (:func:`log_joint_weights`) for the dense E-step, :class:`Terms` with
    ``cand [n, C]`` for the sparse one.

    Precision: the dense E-step's two products (logits ``phi W^T`` and moments
    ``r^T phi``) run at explicit full float32 (:func:`vbgs.inference.precision.matmul`); the sparse
    E-step is in centred form, elementwise only (:func:`vbgs.inference.candidates.candidate_logits`
    and :func:`vbgs.inference.candidates.scatter_moments`).

    ``ray [n, d]``: measured points, each with its noise ``R_n = u_n u_n^T`` along its
    ray (sparse E-step only): responsibilities under the components convolved with the
    noise, and each point's latent surface point under each candidate, ``E[y | x] = x -
    beta u`` with ``Cov[y | x] = gamma u u^T``
    (:func:`vbgs.inference.candidates.candidate_latent`), summed as what the latent
    points differ by from the measured ones: ``Stats.sum_noise = sum r (x x^T - E[y
    y^T | x])`` and ``Stats.sum_shift = sum r (x - E[y | x])`` (the M-step's
    :func:`vbgs.inference.expfam.niw_posterior`).

    ``n_valid`` (a traced int scalar): the batch's real points are its first ``n_valid``,
    the rest padding (weight 0); chunks of padding alone are skipped, not computed (a
    stream pads its frames to a size that only grows, so a frame may carry a third of
    padding), and their entries of the returned ``lse`` are 0.
    """
    n, d = x.shape
    if ray is not None and cand is None:
        raise ValueError("measurement noise (ray) needs the sparse E-step: use estep='sparse'")
    inv2var = 0.5 / colour_noise**2
    n_rows = reference.shape[0] if cand is None else reference.mean.shape[0]

    def one_chunk(acc, batch):
        xb, cb, wb, candb, rayb = batch
        phi = features(xb, cb)  # [chunk, F]
        listed = None
        if partial_lists:
            listed, candb = candb >= 0, jnp.maximum(candb, 0)
        if candb is None:
            logits = feature_logits(phi, reference) - inv2var * jnp.sum(cb**2, -1, keepdims=True)
        elif rayb is None:
            logits = candidates.candidate_logits(xb, cb, reference, candb, colour_noise)
        else:
            logits, beta, gamma = candidates.candidate_latent(xb, cb, reference, candb,
                                                              colour_noise, rayb)
        if listed is not None:  # finite: a point with none listed has weight 0, no NaN
            logits = jnp.where(listed, logits, jnp.finfo(logits.dtype).min / 2)
        lse = jax.nn.logsumexp(logits, -1)  # [chunk]
        resp = jnp.exp(logits - lse[:, None]) * wb[:, None]  # [chunk, k or C]
        if candb is None:
            return acc + precision.matmul(resp.T, phi), lse
        if rayb is None:
            return candidates.scatter_moments(acc, resp, phi, candb), lse
        # two accumulators, not column ranges of one: a slice of the carry set back
        # copies all of it each chunk (~0.5 s a frame at 100k components, 262k points)
        acc, pair = acc
        acc = candidates.scatter_moments(acc, resp, phi, candb)
        # the latent moments, per point and candidate: [chunk, C, d*d + d]
        (b, sym), (g, uu), (_, u) = candidates.latent_moments(beta, gamma, xb, rayb)
        psi = jnp.concatenate([b[..., None] * sym[:, None] + g[..., None] * uu[:, None],
                               b[..., None] * u[:, None]], -1)
        return (acc, candidates.scatter_pair_moments(pair, resp, psi, candb)), lse

    def shape(a):
        return None if a is None else a.reshape((n // chunk, chunk) + a.shape[1:])

    acc0 = jnp.zeros((n_rows, d * d + d + 4), x.dtype)
    if ray is not None:
        acc0 = (acc0, jnp.zeros((n_rows, d * d + d), x.dtype))
    chunks = (shape(x), shape(c), shape(w), shape(cand), shape(ray))
    if n_valid is None:
        acc, lse = jax.lax.scan(one_chunk, acc0, chunks)
    else:  # chunks wholly past the batch's n_valid points are padding: skipped
        def live_chunk(acc, batch):
            start, batch = batch
            return jax.lax.cond(start < n_valid, one_chunk,
                                lambda a, _: (a, jnp.zeros(chunk, x.dtype)), acc, batch)

        starts = jnp.arange(0, n, chunk, dtype=jnp.int32)
        acc, lse = jax.lax.scan(live_chunk, acc0, (starts, chunks))
    if ray is not None:
        acc = jnp.concatenate(acc, -1)
    return moments_to_stats(acc, d), lse.reshape(-1)


# --------------------------------------------------------------------- M-step, ELBO


def m_step(prior: Mixture, stats: Stats) -> Mixture:
    """The conjugate posterior: ``prior + stats`` for every factor."""
    return Mixture(
        expfam.niw_posterior(prior.space, stats),
        expfam.colour_posterior(prior.colour, stats),
        expfam.dirichlet_posterior(prior.alpha, stats),
        prior.origin,
    )


def kl(q: Mixture, p: Mixture, colour_noise: float) -> jnp.ndarray:
    """``KL(q || p)`` summed over all factors and components."""
    return (
        expfam.niw_kl(q.space, p.space).sum()
        + expfam.colour_kl(q.colour, p.colour, colour_noise).sum()
        + expfam.dirichlet_kl(q.alpha, p.alpha)
    )


# ------------------------------------------------------------------ update and fit


def start(prior: Mixture, config: PriorConfig | None = None) -> State:
    """The state before any data: posterior = prior, no statistics, bound to ``config``
    (the hyperparameters every :func:`update` of this state uses; None: unbound)."""
    stats = expfam.zero_stats(prior.n_components, prior.dim, prior.alpha.dtype)
    return State(prior, prior, stats, config)


def bound_config(state: State, config: PriorConfig | None = None) -> PriorConfig:
    """The hyperparameters an update of ``state`` uses: the state's own, else ``config``,
    else the defaults. A ``config`` that differs from the state's is refused: it would
    silently change the likelihood in the middle of a stream."""
    if state.config is None:
        return PriorConfig() if config is None else config
    if config is not None and config != state.config:
        raise ValueError(
            f"config {config} differs from the one this state was started with "
            f"({state.config}); start a new state with model.start(prior, config) to "
            "change hyperparameters, or leave config out"
        )
    return state.config


# Local CAVI of one batch under posterior assignment (see local_cavi): the iterations stop
# once one of them raises the batch's bound L_t by less than LOCAL_TOL nats per point.
# A nat per point is the scale of the bound (about -4 nats per pixel on the image
# task); 1e-3 of it is far above float32 rounding of the summed bound (~1e-7 relative)
# and far below the first iterations' gains (3.5, then 0.08 nats per point, measured on
# the bound of the astronaut patch stream, not on any score of the fit).
LOCAL_TOL = 1e-3
# The most E-steps of a batch's local CAVI (a bound on the cost; a batch that has not
# converged stops here). On the astronaut patch stream (64 px, 2000 components) batches
# converge to LOCAL_TOL in 12 E-steps (median; mean 12.6) and 1 batch of 64 reaches
# the cap, in sequential and in shuffled order.
LOCAL_MAX_ITERS = 30


def local_cavi(state: State, x, c, w, cand, colour_noise: float, chunk: int,
               max_iters: int, tol):
    """The update of one batch under posterior assignment, solved by coordinate ascent.

    Streaming VB treats the posterior before the batch, ``q_{t-1} = state.posterior``,
    as the batch's prior and maximises
    ``L_t(r, q) = sum_nk r_nk (l_nk(q) - log r_nk) - KL(q || q_{t-1})``.
    One E-step under ``q_{t-1}`` is only CAVI's first step: components with no data yet
    (grown for this batch, :mod:`vbgs.inference.grow`) are scored at their prior while their
    neighbours carry covariances fitted to earlier batches, so the batch's points go
    to the wrong components and the fit never revisits them. Here the E-step (under
    ``q_j``) and the M-step (``q_{j+1} = m_step(prior, stats + batch_j)``, which is
    ``q_{t-1}`` plus the batch) alternate until an iteration raises
    ``L_t(r(q_j), q_j) = sum_n lse_n(q_j) - KL(q_j || q_{t-1})`` by less than
    ``tol`` nats per point, or ``max_iters`` E-steps ran (each step never lowers
    ``L_t``). Sparse E-steps keep the candidates ``cand`` found for ``q_{t-1}``.

    Returns the batch statistics and ``lse`` of the last E-step, the model it was taken
    under and the number of E-steps.
    """
    prev = state.posterior
    limit = tol * jnp.sum(w)

    def step(q):
        batch, lse = e_step(q, x, c, w, colour_noise, chunk, cand)
        return batch, lse, jnp.sum(lse * w) - kl(q, prev, colour_noise)

    batch, lse, bound = step(prev)
    q_next = m_step(state.prior, expfam.add_stats(state.stats, batch))

    def cond(carry):
        j, _, _, _, _, gain, _ = carry
        return (j < max_iters) & (gain >= limit)

    def body(carry):
        j, q, _, _, bound, _, _ = carry
        batch, lse, new_bound = step(q)
        q_next = m_step(state.prior, expfam.add_stats(state.stats, batch))
        return j + 1, q_next, batch, lse, new_bound, new_bound - bound, q

    inf = jnp.asarray(jnp.inf, bound.dtype)
    j, _, batch, lse, _, _, q = jax.lax.while_loop(
        cond, body, (jnp.asarray(1), q_next, batch, lse, bound, inf, prev))
    return batch, lse, q, j


@partial(jax.jit, static_argnames=("assign", "colour_noise", "chunk", "local_iters"))
def _update(state: State, x, c, w, cand, assign: Assign, colour_noise: float, chunk: int,
            local_iters: int = 1, local_tol=LOCAL_TOL, ray=None):
    q = state.prior if assign == "prior" else state.posterior
    if assign == "posterior" and local_iters > 1:
        batch, lse, q, _ = local_cavi(state, x, c, w, cand, colour_noise, chunk,
                                      local_iters, local_tol)
    else:  # under the prior the E-step does not depend on q: one step is the solution
        batch, lse = e_step(q, x, c, w, colour_noise, chunk, cand, ray)
    stats = expfam.add_stats(state.stats, batch)
    elbo = jnp.sum(lse * w) - kl(q, state.prior, colour_noise)
    # The unchanged prior is not returned from the compiled function: passing an input
    # straight through to the outputs next to the ELBO reduction made XLA:CPU hang
    # (jax 0.10.2, k >= 10^4); the caller reattaches it.
    return m_step(state.prior, stats), stats, Info(elbo, lse)


def update(
    state: State,
    xyz,
    rgb,
    *,
    assign: Assign = "prior",
    config: PriorConfig | None = None,
    estep: EStep = "dense",
    n_candidates: int = candidates.DEFAULT_CANDIDATES,
    local_iters: int = 1,
    local_tol: float = LOCAL_TOL,
    ray=None,
) -> tuple[State, Info]:
    """Add one batch ``xyz [n, d]``, ``rgb [n, 3]`` (world units) to the state.

    ``assign="prior"``: responsibilities under the fixed prior, so the result does not
    depend on how the data are split or ordered; ``"posterior"``: under the current
    posterior (online variational Bayes, order-dependent). No data are kept.
    ``local_iters`` (posterior assignment only): the most E-steps of the batch's local
    coordinate ascent, stopped when one gains under ``local_tol`` nats per point
    (:func:`local_cavi`); 1 is a single E-step under the posterior before the batch.
    ``info.elbo`` is then taken under the model of the last E-step.
    ``estep="sparse"`` scores each point against its ``n_candidates`` nearest
    components only (:mod:`vbgs.inference.candidates`); ``"dense"`` against all of them.
    ``config``: only needed for an unbound state (see :class:`State` and
    :func:`bound_config`); a bound state's own config is used and a different one refused.
    ``ray [n, d]``: measured points, each with its noise ``u_n u_n^T`` along its ray
    (sparse E-step, one E-step per batch; :func:`e_step_with`).
    """
    config = bound_config(state, config)
    if assign not in ("prior", "posterior"):
        raise ValueError(f"unknown assignment mode {assign!r}: use 'prior' or 'posterior'")
    if estep not in ("dense", "sparse"):
        raise ValueError(f"unknown E-step {estep!r}: use 'dense' or 'sparse'")
    xyz, rgb = check_points_host(xyz, rgb)
    if xyz.shape[1] != state.prior.dim:
        raise ValueError(f"points are {xyz.shape[1]}-D but the model is {state.prior.dim}-D")
    n = xyz.shape[0]
    size = bucket_size(n)
    x, c, w = padded_batch(xyz, rgb, state.prior.origin, size, state.prior.alpha.dtype)
    cand = None
    if estep == "sparse":
        q = state.prior if assign == "prior" else state.posterior
        cand = jnp.asarray(candidates.nearest_components(q.space.mean, x, n_candidates))
        chunk = chunk_size(size, cand.shape[1] * (x.shape[1] ** 2 + x.shape[1] + 4))
    else:
        chunk = chunk_size(size, state.prior.n_components)
    if not isinstance(local_iters, (int, np.integer)) or local_iters < 1:
        raise ValueError(f"local_iters must be a positive integer, got {local_iters!r}")
    if ray is not None and (estep != "sparse" or local_iters > 1):
        raise ValueError("measurement noise (ray) needs estep='sparse' and one E-step "
                         "per batch (local_iters=1)")
    posterior, stats, info = _update(state, x, c, w, cand, assign, float(config.colour_noise),
                                     chunk, int(local_iters), float(local_tol),
                                     padded_rays(ray, n, size, x.dtype))
    return state._replace(posterior=posterior, stats=stats), Info(info.elbo, info.point_loglik[:n])
