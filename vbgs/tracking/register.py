"""The tracker: the camera pose that best explains an RGB-D frame under a map's posterior.

The map's posterior is a mixture of Gaussians over the surface. A frame seen from pose
``T = (R, t)`` puts its depth pixels at the world points ``x_i = R p_i + t`` (``p_i``
the camera-frame points of :func:`vbgs.render.camera.unproject`'s rays); the tracker
maximises their expected log-likelihood under the mixture (a Gaussian-mixture
registration), robustly:

* each point scores only its ``C`` nearest used components (a host KD-tree over the
  posterior means, :mod:`vbgs.inference.candidates`, refreshed once per pass), with
  the E-step's terms (:func:`vbgs.inference.model.component_terms`: ``E[Sigma^-1]``,
  ``E[log pi]``, the log-determinant); the point's distance is
  ``s_i = -2 log sum_c exp(l_ic) + 2 log sum_c exp(const_c)`` (>= 0; the Mahalanobis
  distance when one component explains it); with the frame's colours the E-step's
  colour term joins ``const`` (it decides which component explains a point, so a point
  on a textured wall is drawn along the wall, not only onto it);
* each component's covariance is ``E[Sigma^-1]^-1 = Psi / nu`` plus :data:`COV_FLOOR`
  of its mean variance (a few float32 scale matrices of a map are not quite positive
  definite; a component still singular is left out);
* with a measured depth (``sensor``) the component's covariance gains the point's noise
  along its ray, ``Sigma_k + u_i u_i^T`` (:mod:`vbgs.mapping.measurement`; Sherman-
  Morrison on the precision, as the sparse E-step does);
* the cost is Cauchy's, ``sum_i (c^2 / 2) log(1 + s_i / c^2)``: points the map
  explains badly (occluders, ground seen differently) weigh little; points farther
  than ``reach`` component radii from every component (ground the map has not seen)
  do not count at all;
* the pose moves on the right, ``T exp(xi)`` (:mod:`vbgs.tracking.se3`), by
  Levenberg-Marquardt steps on the Gauss-Newton normal equations of the fixed-
  responsibility (EM) bound, a step kept only if it lowers the cost;
* coarse to fine: few pixels first, with the components' covariances widened by
  ``inflate`` times their own size (a wider basin), then more pixels, the map's own
  covariances. Each level has a fixed point count (pixels drawn at random from those
  with depth under ``seed``; padded and masked when a frame has fewer): every call of
  the compiled solver has the same shapes.

The pose's uncertainty is the inverse Gauss-Newton Hessian at the optimum (a Laplace
approximation treating the frame's pixels as independent draws from the map, so it
is optimistic), scaled from the points used to all the frame's points.

Precision: the solver runs in float32 in a frame centred on the map's origin (world
coordinates up to 60 units keep ~4e-6 units of resolution); quadratic forms are
elementwise products of centred differences (no matrix-unit rounding, as
:mod:`vbgs.inference.precision`); the 6x6 normal equations are summed in float32 and
solved with a Cholesky factorisation after Levenberg-Marquardt damping (their
condition is bounded by using camera-frame Jacobians, rows of magnitude ~depth).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference import candidates as cands
from vbgs.inference import model
from vbgs.inference.precision import logdet3
from vbgs.render.camera import Camera, depth_points, rigid, valid_depth
from vbgs.tracking.degeneracy import Directions, directions, fuse
from vbgs.tracking.se3 import compose, from_rt, orthonormalise, se3_exp

# Points per level, coarse to fine (fixed: one compiled solver per count, whatever the
# map's size).
LEVELS = (512, 2048, 2048)
# The components' covariances are widened by this many times their own RMS radius at
# each level (0: the map as it is).
INFLATE = (1.0, 0.25, 0.0)
# Candidate look-ups per level (each followed by ITERATIONS Levenberg-Marquardt steps):
# the coarse level, cheap, moves farthest (one pass there left a room frame 19 cm and
# 8 degrees from its guess at 1.6 degrees).
PASSES = (3, 2, 1)
ITERATIONS = 6
# Nearest components each point scores.
CANDIDATES = 4
# Cauchy scale c, in units of the point's Mahalanobis distance.
ROBUST = 3.0
# A point counts only within this many RMS component radii of its nearest component.
REACH = 3.0
# Each component's covariance gains this share of its mean variance per axis: a floor
# for the thinnest (and for the few whose float32 scale matrix is not quite positive
# definite); a component still singular after it is left out.
COV_FLOOR = 1e-3
# Fewer points of the final level than this within reach of the map leave every
# direction free (6 fix a pose at best; 24 keep a few outliers from deciding it).
MIN_MATCHED = 24
# Initial Levenberg-Marquardt damping (relative to the Hessian's diagonal) and its
# factors when a step is refused / kept.
DAMPING, DAMP_UP, DAMP_DOWN = 1e-4, 10.0, 0.3


@dataclass(frozen=True)
class TrackConfig:
    """The tracker's settings (module docstring; defaults are the named constants)."""

    levels: tuple[int, ...] = LEVELS
    inflate: tuple[float, ...] = INFLATE
    passes: tuple[int, ...] = PASSES
    iterations: int = ITERATIONS
    candidates: int = CANDIDATES
    robust: float = ROBUST
    reach: float = REACH
    damping: float = DAMPING
    colour_noise: float = model.PriorConfig.colour_noise  # sigma_c of the colour term

    def __post_init__(self):
        if not self.levels or not len(self.levels) == len(self.inflate) == len(self.passes):
            raise ValueError(f"tracking needs one inflate factor and one pass count per "
                             f"level, got levels {self.levels}, inflate {self.inflate} and "
                             f"passes {self.passes}")
        if any(int(n) < 1 for n in self.passes):
            raise ValueError(f"tracking passes must be at least 1 per level, got {self.passes}")
        if any(int(n) < 6 for n in self.levels) or any(f < 0 for f in self.inflate):
            raise ValueError(f"tracking levels need at least 6 points each and inflate "
                             f"factors >= 0, got {self.levels} and {self.inflate}")
        for name in ("iterations", "candidates"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"tracking {name} must be at least 1, got "
                                 f"{getattr(self, name)!r}")
        if not (self.robust > 0 and self.reach > 0 and self.damping > 0
                and self.colour_noise > 0):
            raise ValueError(f"tracking robust, reach, damping and colour_noise must be > 0, "
                             f"got {self.robust}, {self.reach}, {self.damping}, "
                             f"{self.colour_noise}")


# Without a motion guess (the second frame of a track: no velocity yet) the start may be
# a whole frame's motion off (the walk: 0.55 units and 3.6 degrees at 60 frames, along
# a road whose ground and facades barely constrain forward motion): the basin is widened
# first by components 16 and 8 times their size (the default levels left that frame
# where it started; these, at 0.2 mm).
BOOTSTRAP = dict(levels=(512, 512, 512, 2048, 2048), inflate=(16.0, 8.0, 2.0, 0.25, 0.0),
                 passes=(6, 4, 3, 2, 1))


class MapTarget(NamedTuple):
    """A map's posterior as the tracker reads it (built once per frame)."""

    table: np.ndarray  # [13, k] on the host: centred mean (3), E[Sigma^-1]^-1 (6:
    #                    symmetric entries), the E-step's constant (1) and the colour
    #                    mean (3), a column a row
    #                    (gathered on the host: the solver's shapes do not depend on k)
    origin: jax.Array  # [3] the mixture's centred frame
    used: np.ndarray  # [u] the rows of the components that saw data
    tree: object  # KD-tree over the used means (world frame)


class Registration(NamedTuple):
    """A frame's pose from the map and how sure it is."""

    pose: np.ndarray  # [4, 4] camera-to-world, float64
    sigma_t: np.ndarray  # [3] standard deviations of the translation (scene units)
    sigma_r_deg: np.ndarray  # [3] of the rotation (degrees), in the camera frame
    inliers: float  # share of the final level's points within reach of the map
    cost: float  # the final robust cost (per point within reach)
    hessian: np.ndarray  # [6, 6] Gauss-Newton information of the right twist, all points
    free: Directions  # the directions the depth leaves free (vbgs.tracking.degeneracy)


# The symmetric 3x3 entries a table stores, in order; a matrix is a list of 6 planes.
SYM = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _entry(sym, i, j):
    """Entry ``(i, j)`` of a symmetric matrix held as the planes of :data:`SYM`."""
    return sym[SYM.index((min(i, j), max(i, j)))]


def _inverse_sym(a):
    """Inverse (as :data:`SYM` planes) and log-determinant of symmetric positive definite
    matrices held as :data:`SYM` planes, by the adjugate, elementwise."""
    def e(i, j):
        return _entry(a, i, j)

    def cof(i, j):
        r = [x for x in range(3) if x != i]
        c = [x for x in range(3) if x != j]
        minor = e(r[0], c[0]) * e(r[1], c[1]) - e(r[0], c[1]) * e(r[1], c[0])
        return minor if (i + j) % 2 == 0 else -minor

    det = e(0, 0) * cof(0, 0) + e(0, 1) * cof(0, 1) + e(0, 2) * cof(0, 2)
    return [cof(i, j) / det for i, j in SYM], jnp.log(det)


@jax.jit
def _map_table(posterior: model.Mixture) -> jax.Array:
    # the E-step's constant, its log |Psi| elementwise: the table is rebuilt every frame,
    # and batched LAPACK (slogdet) took 4.2 of its 5.7 ms of CPU at 20k components (the
    # terms' precision matrices are unused here: compiled away)
    q = posterior.space  # E[Sigma^-1]^-1 = Psi / nu, floored (module docstring)
    const = model.component_terms(posterior, None, logdet_scale=logdet3(q.scale)).const
    cov = q.scale / q.dof[:, None, None]
    size = jnp.trace(cov, axis1=-2, axis2=-1) / 3.0
    cov = cov + (COV_FLOOR * size)[:, None, None] * jnp.eye(3, dtype=cov.dtype)
    return jnp.stack([*q.mean.T, *(cov[:, i, j] for i, j in SYM), const,
                      *posterior.colour.mean.T], 0)


def target(posterior: model.Mixture, prior: model.Mixture) -> MapTarget:
    """The :class:`MapTarget` of a map's ``posterior`` (components that saw no data,
    ``alpha = prior alpha``, are left out)."""
    used = np.flatnonzero(np.asarray(model.used_components(posterior.alpha - prior.alpha)))
    if len(used) == 0:
        raise ValueError("the map has no component that saw data: nothing to track against")
    means = np.asarray(posterior.space.mean)[used] + np.asarray(posterior.origin)
    return MapTarget(np.asarray(_map_table(posterior)), posterior.origin, used,
                     cands.means_tree(means))


def _cauchy(s, c):
    """Cauchy's cost ``(c^2 / 2) log(1 + s / c^2)`` of squared distances ``s`` and its
    IRLS weight ``1 / (1 + s / c^2)`` (twice its derivative)."""
    return 0.5 * c * c * jnp.log1p(s / (c * c)), 1.0 / (1.0 + s / (c * c))


def _linearise(rot, t, p, u, w, mean, prec, const, robust):
    """Cost, gradient ``[6]`` and Gauss-Newton Hessian ``[6, 6]`` of the right
    perturbation at pose ``(rot, t)`` (``t`` in the map's centred frame). Points and
    their ray noise (camera frame) are lists of 3 planes ``[n]``, ``w [n]`` their
    weights; the candidates' ``mean`` 3 planes ``[n, C]``, ``prec`` 6 :data:`SYM`
    planes ``[n, C]``, ``const [n, C]``. Elementwise planes throughout (small trailing
    axes vectorise badly on CPUs; no matrix-unit rounding)."""
    y = [sum(rot[i, j] * p[j] for j in range(3)) for i in range(3)]  # R p: [n] each
    d = [(y[i] + t[i])[:, None] - mean[i] for i in range(3)]  # [n, C] each
    uw = [sum(rot[i, j] * u[j] for j in range(3))[:, None] for i in range(3)]

    def pe(i, j):
        return _entry(prec, i, j)

    pu = [sum(pe(i, j) * uw[j] for j in range(3)) for i in range(3)]
    q = sum(uw[i] * pu[i] for i in range(3))
    eff = [pe(i, j) - pu[i] * pu[j] / (1.0 + q) for i, j in SYM]  # (P^-1 + u u^T)^-1
    maha = sum((1.0 if i == j else 2.0) * eff[m] * d[i] * d[j] for m, (i, j) in enumerate(SYM))
    logits = const - 0.5 * (maha + jnp.log1p(q))
    s = jnp.maximum(-2.0 * (jax.nn.logsumexp(logits, -1) - jax.nn.logsumexp(const, -1)), 0.0)
    rho, weight = _cauchy(s, robust)
    r = jax.nn.softmax(logits, -1)  # the fixed-responsibility (EM) bound
    pbar = [jnp.sum(r * e, -1) for e in eff]  # [n] each
    gx = [jnp.sum(r * sum(_entry(eff, i, j) * d[j] for j in range(3)), -1) for i in range(3)]
    # J_y = [I, -[y]x]: H = [[P, -P[y]x], [., [y]x^T P [y]x]], g = [gx, y x gx]
    cross = [[0.0, -y[2], y[1]], [y[2], 0.0, -y[0]], [-y[1], y[0], 0.0]]  # [y]x
    pm = [[sum(_entry(pbar, i, j) * cross[j][m] for j in range(3)) for m in range(3)]
          for i in range(3)]  # P [y]x
    rr = [[sum(cross[i][m] * pm[i][n] for i in range(3)) for n in range(3)] for m in range(3)]
    blocks = ([_entry(pbar, i, j) for i in range(3) for j in range(3)]
              + [-pm[i][m] for i in range(3) for m in range(3)]
              + [rr[m][n] for m in range(3) for n in range(3)]
              + gx + [y[1] * gx[2] - y[2] * gx[1], y[2] * gx[0] - y[0] * gx[2],
                      y[0] * gx[1] - y[1] * gx[0]])
    ww = w * weight
    sums = jnp.stack([jnp.sum(ww * b) for b in blocks])
    tt, tr, rr_, g_y = (sums[:9].reshape(3, 3), sums[9:18].reshape(3, 3),
                        sums[18:27].reshape(3, 3), sums[27:])
    h_y = jnp.block([[tt, tr], [tr.T, rr_]])
    b = jax.scipy.linalg.block_diag(rot, rot)  # J = J_y blockdiag(R, R)
    hp = jax.lax.Precision.HIGHEST
    h = jnp.matmul(b.T, jnp.matmul(h_y, b, precision=hp), precision=hp)
    return jnp.sum(w * rho), jnp.matmul(b.T, g_y, precision=hp), h


@partial(jax.jit, static_argnames=("iterations",))
def _solve(pose, p, u, rgb, w, cols, origin, inflate, robust, reach, damping, colour_noise,
           *, iterations: int):
    """Levenberg-Marquardt on one level's points ``p``, ``u``, ``rgb [n, 3]`` with fixed
    candidates (nearest first), whose :class:`MapTarget` table columns are ``cols [13,
    n, C]``: the final pose, its cost, Hessian and the points' weights after the reach
    test."""
    mean, cov, const = cols[:3], list(cols[3:9]), cols[9]
    # the E-step's colour term: it picks which component explains a point (not where)
    const = const - 0.5 * sum((rgb[:, i, None] - cols[10 + i]) ** 2
                              for i in range(3)) / colour_noise**2
    size = (cov[0] + cov[3] + cov[5]) / 3.0  # [n, C] the mean variance per axis
    widened = [c + (inflate**2 * size if i == j else 0.0)
               for c, (i, j) in zip(cov, SYM, strict=True)]
    prec_l, logdet_l = _inverse_sym(widened)
    _, logdet = _inverse_sym(cov)
    ok = jnp.isfinite(logdet_l) & jnp.isfinite(logdet)  # singular components left out
    const = jnp.where(ok, const - 0.5 * (logdet_l - logdet), -1e30)  # the widening's
    prec_l = [jnp.where(ok, e, 0.0) for e in prec_l]  # change of log |P|
    p, u = list(p.T), list(u.T)
    rot, t = pose[:3, :3], pose[:3, 3] - origin
    x0 = [sum(rot[i, j] * p[j] for j in range(3)) + t[i] for i in range(3)]
    dist2 = sum((x0[i] - mean[i][:, 0]) ** 2 for i in range(3))
    # unseen ground is out: farther than reach radii of the (widened) nearest component
    # and the point's own depth noise
    noise2 = sum(u[i] ** 2 for i in range(3))
    w = w * (dist2 <= reach**2 * (3.0 * (1.0 + inflate**2) * size[:, 0] + noise2)) * ok[:, 0]

    def lin(rot, t):
        return _linearise(rot, t, p, u, w, mean, prec_l, const, robust)

    def body(_, carry):
        # evaluate the pose tried; keep it if it lowers the cost (the first always:
        # the start pose); then the damped step from the pose kept is the next try
        rot, t, cost, g, h, lam, tried = carry
        cost2, g2, h2 = lin(tried[:3, :3], tried[:3, 3])
        better = jnp.isfinite(cost2) & (cost2 < cost)
        keep = lambda new, old: jnp.where(better, new, old)  # noqa: E731
        rot, t, cost, g, h = (keep(tried[:3, :3], rot), keep(tried[:3, 3], t),
                              keep(cost2, cost), keep(g2, g), keep(h2, h))
        lam = jnp.where(better, lam * DAMP_DOWN, lam * DAMP_UP)
        diag = jnp.diag(h)
        a = h + jnp.diag(lam * diag + 1e-12 * jnp.max(diag) + 1e-30)
        step = -jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(a), g)
        return rot, t, cost, g, h, lam, compose(from_rt(rot, t), se3_exp(step))

    start = from_rt(rot, t)
    zero = jnp.zeros((), pose.dtype)
    rot, t, cost, g, h, _, _ = jax.lax.fori_loop(
        0, iterations + 1, body,
        (rot, t, zero + jnp.inf, jnp.zeros(6, pose.dtype), jnp.zeros((6, 6), pose.dtype),
         zero + damping / DAMP_DOWN, start))
    return from_rt(rot, t + origin), cost, h, w


def _draw(n_valid: int, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` point indices among ``n_valid`` (without repeats while there are enough;
    padded with index 0 and weight 0 beyond) and their weights."""
    if n_valid >= n:
        return np.sort(rng.choice(n_valid, n, replace=False)), np.ones(n, np.float32)
    idx = np.zeros(n, np.int64)
    idx[:n_valid] = np.arange(n_valid)
    return idx, (np.arange(n) < n_valid).astype(np.float32)


def register(map_target: MapTarget, camera: Camera, depth: np.ndarray, guess,
             config: TrackConfig = TrackConfig(), *, rgb: np.ndarray | None = None,
             ray: np.ndarray | None = None, seed: int = 0) -> Registration:
    """The pose ``[4, 4]`` (camera-to-world) of a frame ``depth [h, w]`` seen by
    ``camera`` (its intrinsics only: its pose is never read) under the map, starting
    from ``guess [4, 4]``. ``rgb [h, w, 3]``: the frame's colours (the E-step's colour
    term then picks each point's components; None: position only). ``ray [n, 3]``:
    each valid pixel's depth noise along its ray in the camera frame
    (:func:`vbgs.mapping.measurement.point_rays` with an identity pose; None: exact
    depth). ``seed`` draws the pixels of each level."""
    p_all = depth_points(camera, depth).astype(np.float32)  # camera frame, pose unread
    colours, noise = np.zeros_like(p_all), np.inf
    if rgb is not None:
        colours = np.asarray(rgb, np.float32)[valid_depth(np.asarray(depth))]
        noise = float(config.colour_noise)
    if len(p_all) < 6:
        raise ValueError(f"the frame has {len(p_all)} pixels with valid depth: a pose "
                         f"needs at least 6")
    if ray is not None and np.shape(ray) != p_all.shape:
        raise ValueError(f"ray must hold one noise vector per valid depth pixel "
                         f"{p_all.shape}, got {np.shape(ray)}")
    rng = np.random.default_rng([seed, 26])
    pose = orthonormalise(np.asarray(guess, np.float64))
    dtype = map_target.table.dtype
    robust, reach = float(config.robust), float(config.reach)
    k = min(int(config.candidates), len(map_target.used))
    for n, inflate, passes in zip(config.levels, config.inflate, config.passes, strict=True):
        idx, w = _draw(len(p_all), int(n), rng)
        p = p_all[idx]
        u = np.zeros_like(p) if ray is None else np.asarray(ray, np.float32)[idx]
        c = jnp.asarray(colours[idx])
        for _ in range(int(passes)):
            world = rigid(p.astype(np.float64), pose)
            cand = map_target.used[cands.query(map_target.tree, world, k)]
            out, cost, h, w_used = _solve(
                jnp.asarray(pose, dtype), jnp.asarray(p), jnp.asarray(u), c, jnp.asarray(w),
                jnp.asarray(map_target.table[:, cand]), map_target.origin, inflate, robust,
                reach, float(config.damping), noise, iterations=int(config.iterations))
            pose = orthonormalise(np.asarray(out, np.float64))
    n_in = float(np.sum(np.asarray(w_used)))
    scale = len(p_all) / max(float(np.sum(w)), 1.0)  # Hessian of all the frame's points
    hess = np.asarray(h, np.float64) * scale
    free = directions(hess, p_all, matched=int(n_in), min_matched=MIN_MATCHED)
    _, cov = fuse(pose, hess, free)  # free directions: infinite (nothing else fixes them)
    sigma = np.sqrt(np.abs(np.diag(cov)))
    return Registration(pose, sigma[:3], np.degrees(sigma[3:]), n_in / max(np.sum(w), 1.0),
                        float(cost) / max(n_in, 1.0), hess, free)
