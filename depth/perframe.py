"""Each frame's depth aligned to the frames that arrived before it (per-frame alignment).

A depth network's depth, even after one alignment for the whole stream
(:mod:`depth.stream`; what the ``mono`` sensor model of :mod:`vbgs.sensors.mono`
simulates), is wrong in each frame its own way: a scale (3 %) and a shift (2 % of the
median depth) of its own and a smooth warp (up to 5 %). A surface seen by several
frames is then learned at several depths. Each arriving frame ``i`` is therefore
corrected, before the learner sees it, by

    d'(u) = d(u) * sum_k c_k phi_k(u) + b

(``phi_k`` the monomials of the image coordinates, scaled to [-1, 1], up to
``warp_order``; ``phi_0 = 1``), fitted against the already-aligned frames that arrived
before it (the last ``window`` of them) with their known poses. Only arrived frames are
read: the first frame of a stream, whatever its file, is left as it came, and a reversed
stream aligns on its own first frames.

The fit. Each of frame ``i``'s pixels with depth is placed at ``X(d') = c_i + d' R_i
r(u)`` and looked up in each reference frame ``j`` (backward warping: bilinear in
``j``'s depth, all four corners with depth and within ``agree`` of each other, so a
depth edge is never interpolated across). The point's depth in ``j``'s camera is linear
in the corrected depth, ``z_j = alpha d' + beta`` (``alpha = (R_j^T R_i r(u))_z``,
``beta = (R_j^T (c_i - c_j))_z``), and should equal ``j``'s depth there; pixels that
disagree by more than ``agree`` (occlusions, a surface ``j`` does not see) are left out.
The coefficients minimise Tukey's biweight of the residuals (IRLS, the sigma from the
MAD) plus ridge terms: ``ridge`` on the non-constant warp terms (toward 0: extrapolated
outside the overlap they would bend the frame), ``shift_ridge`` on ``b`` (toward 0: over
one frame's narrow depth range a shift is nearly a scale) and ``shrink`` on ``c_0``
(toward 1: the network's own alignment), each relative to the fit's summed weight, so
``shrink = 1`` goes half-way to the references. Where a point lands in ``j``, and so
``j``'s depth there, moves with ``d'`` too: each of the ``OUTER`` Gauss-Newton steps
linearises ``alpha d' + beta - z_j(d')`` with the slope of ``z_j`` along the ray taken by
finite differences (a reference surface almost along the frame's ray, slope within
``MIN_SLOPE`` of ``alpha``, fixes nothing and is left out). Treating ``z_j`` as fixed
recovered a 4 % scale error as 3 % on the object at 32 px. Fewer than ``min_pairs``
pixels seen by both: the frame is left as it came.

Why against the arrived frames and not the map: a previous attempt, rescaling each frame
to the map's rendered depth, made it worse (14.06 against 15.61 dB on the object at 128
px, 20k components, 60 frames): rendered depth is alpha-blended at edges and an early map
is incomplete. Why backward warping: a z-buffered forward warp keeps the nearest of the
several points that land in a pixel, a bias toward the camera on inclined surfaces that
showed as a spurious tilt of 5-13 % in the fitted warp. Why ``shrink``: the references are
aligned frames themselves, so a frame pinned to them inherits the first frame's error and
the chain drifts (a random walk of the fit errors: from 3 to 40 % depth error by the 20th
frame of the object with no shrink and a linear warp); pulled half-way toward the
network's own alignment, the errors stay bounded.

The defaults (a linear warp, ``ridge = shrink = shift_ridge = 1``, a window of 8) were
chosen on validation views of the object under the ``mono`` sensor model, against no
per-frame alignment, scale and shift alone, a stronger shrink, a wider window and a
quadratic warp; no results table holds the grid: docs/validation.md
("depth.perframe") keeps it. What is left after the alignment is mostly the depth bled
across silhouettes, not the alignment's to remove.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.render.pixels import pixel_rays

WINDOW = 8  # the most recent aligned frames read as references
WARP_ORDER = 1  # polynomial order, in image coordinates, of the multiplicative correction
AGREE = float(np.log(1.1))  # a reference's depth within 10 % of the point's (log)
MIN_PAIRS = 64  # fewer pixels seen by both: the frame is left as it came
RIDGE = 1.0  # pull of the non-constant warp terms toward 0 (relative to the data)
SHIFT_RIDGE = 1.0  # pull of the shift toward 0
SHRINK = 1.0  # pull of the scale term toward 1 (the network's own alignment)
OUTER = 5  # Gauss-Newton steps (where the points land in the references moves with d')
STEP = 1e-3  # relative step of the finite difference d z_ref / d d'
MIN_SLOPE = 0.2  # a reference's depth must change by less than 0.8 of the point's:
# a reference surface almost along the frame's ray fixes nothing
IRLS_STEPS = 20
TUKEY_C = 4.685  # Tukey's biweight constant (95 % efficiency under Gaussian noise)
MAD_TO_SIGMA = 1.4826  # sigma = 1.4826 * MAD for Gaussian residuals


class FrameAlignConfig(NamedTuple):
    """How each frame is aligned to the frames that arrived before it."""

    window: int = WINDOW
    warp_order: int = WARP_ORDER
    agree: float = AGREE
    min_pairs: int = MIN_PAIRS
    ridge: float = RIDGE
    shrink: float = SHRINK
    shift_ridge: float = SHIFT_RIDGE


class Reference(NamedTuple):
    """An aligned frame kept as reference."""

    camera: object
    depth: np.ndarray  # [h, w] aligned, 0 = no depth


class AlignState(NamedTuple):
    """The aligned frames kept (the last ``window``) and the count of arrivals."""

    frames: tuple = ()
    arrived: int = 0


class FrameFit(NamedTuple):
    """One frame's correction: ``d' = d * sum_k coef_k phi_k(x, y) + shift``."""

    coef: tuple
    shift: float
    n_pairs: int
    residual: float  # median |d' - ref| / ref over the pairs kept


IDENTITY_FIT = FrameFit((1.0,), 0.0, 0, float("nan"))


def init() -> AlignState:
    return AlignState()


def _sample(depth: np.ndarray, u: np.ndarray, v: np.ndarray, spread: float):
    """Bilinear ``depth`` at pixel coordinates ``(u, v)`` (pixel centres at +0.5), nan
    where a corner has no depth or the corners differ by more than ``spread`` (log)."""
    h, w = depth.shape
    x, y = u - 0.5, v - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    ok = (x0 >= 0) & (y0 >= 0) & (x0 + 1 < w) & (y0 + 1 < h)
    x0, y0 = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
    c = np.stack([depth[y0, x0], depth[y0, x0 + 1], depth[y0 + 1, x0], depth[y0 + 1, x0 + 1]])
    ok &= (c > 0).all(0)
    with np.errstate(divide="ignore", invalid="ignore"):
        lc = np.log(np.where(c > 0, c, 1.0))
    ok &= (lc.max(0) - lc.min(0)) < spread
    val = (c[0] * (1 - fx) * (1 - fy) + c[1] * fx * (1 - fy) + c[2] * (1 - fx) * fy
           + c[3] * fx * fy)
    return np.where(ok, val, np.nan)


def _pairs(world_dir: np.ndarray, centre: np.ndarray, reference: Reference):
    """The target's valid pixels' rays ``world_dir [n, 3]`` (world directions at unit
    camera depth) from its camera centre ``centre [3]``, in the reference's frame: the
    rays ``[n, 3]`` and the centre's offset ``[3]``."""
    rpose = np.asarray(reference.camera.pose, np.float64)
    in_ref = world_dir @ rpose[:3, :3]  # [n, 3] the ray in the reference's frame
    off = (centre - rpose[:3, 3]) @ rpose[:3, :3]  # [3]
    return in_ref, off


def _lookup(d_new, in_ref, off, reference: Reference, spread: float):
    """The reference's depth where it sees the target's points at depth ``d_new``, and
    the points' camera depth there."""
    x = d_new[:, None] * in_ref + off  # [n, 3]
    z = x[:, 2]
    cam = reference.camera
    with np.errstate(divide="ignore", invalid="ignore"):
        u = cam.fx * x[:, 0] / z + cam.cx
        v = cam.fy * x[:, 1] / z + cam.cy
    u = np.where(z > 1e-9, u, -1.0)
    v = np.where(z > 1e-9, v, -1.0)
    return _sample(np.asarray(reference.depth, np.float64), u, v, spread), z


def basis(h: int, w: int, order: int) -> np.ndarray:
    """``[h, w, m]``: the monomials ``x^i y^j`` (``i + j <= order``) of the image
    coordinates scaled to [-1, 1]; the first is 1."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    x = (x + 0.5) / w * 2 - 1
    y = (y + 0.5) / h * 2 - 1
    terms = [x**i * y**(d - i) for d in range(order + 1) for i in range(d, -1, -1)]
    return np.stack(terms, -1)


def _solve(a, y, theta, prior_w, prior_mu):
    """Tukey IRLS of ``a theta ~ y`` from ``theta``, with a ridge ``prior_w`` (relative
    to the summed weight and the columns' scale) toward ``prior_mu``."""
    col_scale = np.sqrt((a**2).mean(0))
    scale_y = float(np.median(np.abs(y)))
    for _ in range(IRLS_STEPS):
        r = a @ theta - y
        sigma = max(MAD_TO_SIGMA * float(np.median(np.abs(r))), 1e-9 * scale_y)
        u = r / (TUKEY_C * sigma)
        wt = np.where(np.abs(u) < 1, (1 - u**2) ** 2, 0.0)
        lam = prior_w * wt.sum() * col_scale**2
        lhs = (a * wt[:, None]).T @ a + np.diag(lam)
        rhs = (a * wt[:, None]).T @ y + lam * prior_mu
        new = np.linalg.solve(lhs, rhs)
        done = np.max(np.abs(new - theta)) < 1e-9 * max(1.0, np.max(np.abs(theta)))
        theta = new
        if done:
            break
    return theta


def fit(depth: np.ndarray, camera, references, config: FrameAlignConfig) -> FrameFit:
    """The correction of ``depth [h, w]`` (seen by ``camera``) that brings its points to
    where the ``references`` (aligned frames) see them: each target pixel's point is
    looked up in each reference (bilinear, all four corners with depth); where the
    reference's depth agrees within ``agree``, ``z_ref(d') = alpha d' + beta`` (the
    point's depth in the reference frame, linear in the corrected depth ``d'``) should
    equal it. Robust (Tukey) Gauss-Newton: the reference's depth where the point lands
    moves with ``d'`` too (slope by finite differences), ``OUTER`` steps."""
    depth = np.asarray(depth, np.float64)
    h, w = depth.shape
    phi_map = basis(h, w, config.warp_order)  # [h, w, m]
    m = phi_map.shape[-1]
    ok = depth > 0  # the target's rays, once for every reference
    rays = pixel_rays(camera.height, camera.width, camera.fx, camera.fy, camera.cx,
                      camera.cy)[ok]  # [n, 3]
    pose = np.asarray(camera.pose, np.float64)
    world_dir = rays @ pose[:3, :3].T  # [n, 3]
    d, phi = depth[ok], phi_map[ok]
    parts = [(_pairs(world_dir, pose[:3, 3], r), r) for r in references]
    theta = np.zeros(m + 1)
    theta[0] = 1.0
    prior_w = np.full(m + 1, float(config.ridge))
    prior_w[0] = config.shrink
    prior_w[m] = config.shift_ridge
    prior_mu = np.zeros(m + 1)
    prior_mu[0] = 1.0
    n_used, res = 0, float("nan")
    for _ in range(OUTER):
        rows, ys, zs = [], [], []
        for (in_ref, off), r in parts:
            d_new = d * (phi @ theta[:m]) + theta[m]
            z_ref, _ = _lookup(d_new, in_ref, off, r, config.agree)
            z_far, _ = _lookup(d_new * (1 + STEP), in_ref, off, r, config.agree)
            alpha, beta = in_ref[:, 2], off[2]
            z_pt = alpha * d_new + beta
            with np.errstate(divide="ignore", invalid="ignore"):
                slope_ref = (z_far - z_ref) / (STEP * d_new)  # d z_ref / d d'
                good = (np.isfinite(z_ref) & np.isfinite(z_far) & (z_pt > 0)
                        & (np.abs(np.log(z_pt / z_ref)) < config.agree)
                        & (alpha - slope_ref > MIN_SLOPE * alpha))
            slope, g = (alpha - slope_ref)[good], slope_ref[good]
            a = np.concatenate([d[good, None] * phi[good], np.ones((good.sum(), 1))], 1)
            rows.append(slope[:, None] * a)
            ys.append(z_ref[good] - beta - g * d_new[good])
            zs.append(z_ref[good])
        a, y = np.concatenate(rows), np.concatenate(ys)
        n_used = len(y)
        if n_used < config.min_pairs:
            return IDENTITY_FIT._replace(n_pairs=int(n_used))
        theta = _solve(a, y, theta, prior_w, prior_mu)
        res = float(np.median(np.abs(a @ theta - y) / np.concatenate(zs)))
    return FrameFit(tuple(float(c) for c in theta[:m]), float(theta[m]), int(n_used), res)


def apply(fit_: FrameFit, depth: np.ndarray, order: int) -> np.ndarray:
    depth = np.asarray(depth, np.float64)
    h, w = depth.shape
    order = order if len(fit_.coef) > 1 else 0
    mult = basis(h, w, order) @ np.asarray(fit_.coef)
    out = depth * mult + fit_.shift
    return np.where((depth > 0) & (out > 0), out, 0.0).astype(np.float32)


def align_frame(state: AlignState, camera, depth: np.ndarray, config: FrameAlignConfig
                ) -> tuple[AlignState, np.ndarray, FrameFit]:
    """One frame arrives with its (globally aligned) surface depth: the new state, its
    aligned depth ``[h, w]`` float32 and the correction fitted."""
    f = fit(depth, camera, state.frames, config) if state.frames else IDENTITY_FIT
    out = apply(f, depth, config.warp_order)
    frames = (*state.frames, Reference(camera, out))[-config.window:]
    return AlignState(frames, state.arrived + 1), out, f
