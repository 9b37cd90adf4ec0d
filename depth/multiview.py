"""Metric depth from a depth network's relative predictions, by the views themselves.

A relative network gives depth up to an unknown map ``d = f(p; s, t)`` of its output
``p``: ``d = s p + t`` ("relative", affine-invariant depth) or ``1 / d = s p + t``
("inverse", disparity), as :func:`depth.align.apply` writes it. Without any sensor
depth, the known camera poses fix ``(s, t)``: only the right map puts the views'
points where the other views see them. For views ``a`` and ``b`` with camera-to-world
``(R_a, c_a)``, ``(R_b, c_b)`` and a pixel ``u`` of ``a`` with ray ``r_a(u)`` (camera
frame, unit z), the point

    X = c_a + f(p_a(u)) R_a r_a(u)

is seen by ``b`` at camera-frame ``x_b = R_b^T (X - c_b)``, pixel ``v = pi(x_b)`` and
depth ``z_ab = x_b[2]``. Where ``b`` sees the same surface the colours agree,
``rgb_a(u) = rgb_b(v)``. The alignment minimises over ``(s, t)`` the photometric cost

    C(s, t) = mean_{a != b, u} min(|rgb_a(u) - rgb_b(v)|^2 / sc^2, 1)

(``|.|^2`` the mean over channels, ``sc = COLOUR_SIGMA``), truncated so occlusions, the
sky and moving things cost at most 1 each. A point whose depth is not positive under
``(s, t)``, at ``u`` or at ``v``, costs 2; a point ``b`` does not see (behind it, outside
the image) costs 1, as a point it sees elsewhere would (a map that pushes points out of
view explains nothing). A global scale error ``(1 + e)`` moves ``X`` by ``e`` times its
depth along ``a``'s ray; ``b`` sees that as a shift of about ``e |c_a - c_b| f / z`` px
along the epipolar line, which the colours detect where there is texture: the pixels
``u`` are drawn among the ``TEXTURE_SHARE`` of each view with the steepest colour
gradient (at least ``MIN_GRADIENT``), since on a uniform colour (a white backdrop, the
sky) every map agrees. The views must have a baseline (a pure rotation has none:
refused). The depths' own agreement, ``g = log(z_ab / f(p_b(v)))``, is not in the cost:
a constant depth agrees with itself across neighbouring views, and with the mono
model's per-frame drift (3-5 %) it scored better than the truth (0.75 against 1.12 on
the object, 6 of 60 views at 64 px); it is reported (``residual``, inliers within
``GEO_SIGMA``).

The search runs on the depths ``(z1, z2)`` the map gives two prediction quantiles
(``QUANTILES`` of the predictions at the drawn pixels or, where those share one value,
of the distinct values of every pixel) rather than on ``(s, t)``: both are depths, so
their range is known from the poses, ``z1`` in ``DEPTH_SPAN`` times the views' median
baseline and ``z2 / z1`` up to ``RATIO_SPAN``, on the side the kind says (``p1 < p2``:
an inverse model's ``z2 < z1``, a relative model's ``z2 > z1``; the map is monotone the
model's way, so a view can never be turned inside out). The basin of the truth is
narrow (a 10 % scale error costs more than a flat plane), so a log grid of ``GRID``
points, scored with ``sc`` and with ``WIDEN * sc``, gives the ``STARTS`` best starts
for Nelder-Mead, and the lowest end wins.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depth.align import Alignment, apply
from vbgs.render.pixels import pixel_rays

SPACE = {"relative": "depth", "inverse": "inverse"}
SAMPLES = 512  # pixels drawn per view
TEXTURE_SHARE = 0.3  # pixels drawn among this share of a view with the steepest gradient
MIN_GRADIENT = 0.02  # ... and at least this colour gradient (per pixel, RGB in [0, 1])
GEO_SIGMA = float(np.log(1.1))  # a point agrees in depth within 10 % (reported inliers)
COLOUR_SIGMA = 0.1  # colour residual (RGB in [0, 1]) that costs 1
QUANTILES = (20.0, 80.0)  # the prediction values whose depths are searched
DEPTH_SPAN = (0.2, 200.0)  # z1 relative to the median baseline between the views
RATIO_SPAN = 6.0  # z2 / z1 in [1, RATIO_SPAN] (relative) or [1 / RATIO_SPAN, 1] (inverse)
GRID = (32, 17)  # log z1 x log(z2 / z1) grid points
WIDEN = 3.0  # the grid is scored with the sigmas as given and this much wider
STARTS = 4  # descents from the best grid points
MIN_BASELINE = 1e-6  # relative to the views' distance from their centroid, plus 1e-12


class View(NamedTuple):
    """One arrived frame as the alignment reads it."""

    camera: object  # vbgs.render.camera.Camera
    rgb: np.ndarray  # [h, w, 3] in [0, 1]
    prediction: np.ndarray  # [h, w] the network's output


class _Pairs(NamedTuple):
    """Every sampled pixel of every view against every other view, flattened: [q]."""

    p_src: np.ndarray  # [q] prediction at the source pixel
    rgb_src: np.ndarray  # [q, 3]
    dir_b: np.ndarray  # [q, 3] source ray (unit z in the source frame) in target's frame
    off_b: np.ndarray  # [q, 3] source centre in the target's frame
    target: np.ndarray  # [q] target view index
    intr: np.ndarray  # [q, 4] target fx, fy, cx, cy
    size: np.ndarray  # [q, 2] target width, height
    p_maps: np.ndarray  # [m, h * w] predictions, flattened (one size for all views)
    rgb_maps: np.ndarray  # [m, h * w, 3]


def baselines(views: list[View]) -> np.ndarray:
    """Distances ``[m * (m - 1) / 2]`` between the views' camera centres."""
    c = np.stack([np.asarray(v.camera.pose, np.float64)[:3, 3] for v in views])  # [m, 3]
    i, j = np.triu_indices(len(c), 1)
    return np.linalg.norm(c[i] - c[j], axis=1)


def check_views(views: list[View]) -> float:
    """The views' median baseline, or ValueError when they cannot fix a scale: fewer
    than two views, views of different sizes, or no baseline (one camera centre)."""
    if len(views) < 2:
        raise ValueError(f"aligning a depth network's output by the views needs at least 2 "
                         f"views with a baseline, got {len(views)}; give a few frames of "
                         f"sensor depth (--depth-reference sensor) or a metric model "
                         f"(--depth-kind metric)")
    if len({v.prediction.shape for v in views}) != 1:
        raise ValueError("the views to align must have one image size; resize the frames")
    b = baselines(views)
    c = np.stack([np.asarray(v.camera.pose, np.float64)[:3, 3] for v in views])
    spread = float(np.linalg.norm(c - c.mean(0), axis=1).max())
    if b.max() <= MIN_BASELINE * spread + 1e-12:
        raise ValueError(f"the {len(views)} views aligned on share one camera centre (a pure "
                         f"rotation has no baseline), so the depth scale cannot be found "
                         f"from them; give a few frames of sensor depth (--depth-reference "
                         f"sensor) or a metric model (--depth-kind metric)")
    return float(np.median(b[b > 0]))


def textured(rgb: np.ndarray) -> np.ndarray:
    """``[h, w]`` bool: the ``TEXTURE_SHARE`` of the pixels with the steepest colour
    gradient (central differences, summed over channels), at least ``MIN_GRADIENT``."""
    rgb = np.asarray(rgb, np.float64)
    gy, gx = np.gradient(rgb, axis=(0, 1))
    grad = np.sqrt((gx**2 + gy**2).sum(-1))  # [h, w]
    return (grad >= np.quantile(grad, 1.0 - TEXTURE_SHARE)) & (grad >= MIN_GRADIENT)


def _pairs(views: list[View], rng: np.random.Generator) -> _Pairs:
    h, w = views[0].prediction.shape
    parts = []
    for a, va in enumerate(views):
        ok = np.flatnonzero((np.isfinite(va.prediction) & textured(va.rgb)).ravel())
        if not len(ok):
            continue
        idx = rng.choice(ok, min(SAMPLES, len(ok)), replace=False)  # [n]
        cam = va.camera
        rays = pixel_rays(h, w, cam.fx, cam.fy, cam.cx, cam.cy).reshape(-1, 3)[idx]  # [n, 3]
        pose_a = np.asarray(va.camera.pose, np.float64)
        world = rays @ pose_a[:3, :3].T  # [n, 3] ray directions in the world
        for b, vb in enumerate(views):
            if a == b:
                continue
            pose_b = np.asarray(vb.camera.pose, np.float64)
            rot_t = pose_b[:3, :3].T
            parts.append((va.prediction.ravel()[idx], va.rgb.reshape(-1, 3)[idx],
                          world @ rot_t.T, np.broadcast_to(rot_t @ (pose_a[:3, 3] - pose_b[:3, 3]),
                                                           (len(idx), 3)),
                          np.full(len(idx), b),
                          np.broadcast_to([vb.camera.fx, vb.camera.fy, vb.camera.cx,
                                           vb.camera.cy], (len(idx), 4)),
                          np.broadcast_to([w, h], (len(idx), 2))))
    if not parts:
        raise ValueError("the views to align show no texture (a uniform colour): the depth "
                         "scale cannot be found from them; give a few frames of sensor "
                         "depth (--depth-reference sensor)")
    cols = [np.concatenate(c).astype(np.float64) for c in zip(*parts, strict=True)]
    return _Pairs(*cols[:4], cols[4].astype(np.int64), cols[5], cols[6].astype(np.int64),
                  np.stack([v.prediction.ravel() for v in views]).astype(np.float64),
                  np.stack([v.rgb.reshape(-1, 3) for v in views]).astype(np.float64))


def _map(space: str, p: np.ndarray, s: float, t: float) -> np.ndarray:
    """:func:`depth.align.apply` in float64 on sampled arrays (0: no depth)."""
    return apply(Alignment(s, t, space, float("nan"), float("nan"), 0), p).astype(np.float64)


def _from_depths(space: str, p12: tuple[float, float], z12) -> tuple[float, float]:
    """``(s, t)`` of the map that sends the predictions ``p12`` to the depths ``z12``."""
    (p1, p2), (z1, z2) = p12, z12
    y1, y2 = (1 / z1, 1 / z2) if space == "inverse" else (z1, z2)
    s = (y2 - y1) / (p2 - p1)
    return float(s), float(y1 - s * p1)


def _residuals(pairs: _Pairs, space: str, s: float, t: float, widen: float = 1.0):
    """Per point: cost ``[q]`` (nan: not seen by the target), log-depth residual ``[q]``."""
    z = _map(space, pairs.p_src, s, t)  # [q]
    x = z[:, None] * pairs.dir_b + pairs.off_b  # [q, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = pairs.intr[:, 0] * x[:, 0] / x[:, 2] + pairs.intr[:, 2]
        v = pairs.intr[:, 1] * x[:, 1] / x[:, 2] + pairs.intr[:, 3]
    seen = (z <= 0) | ((x[:, 2] > 0) & (u >= 0) & (u < pairs.size[:, 0]) & (v >= 0)
                       & (v < pairs.size[:, 1]))
    col = np.clip(np.floor(np.nan_to_num(u)), 0, pairs.size[:, 0] - 1).astype(np.int64)
    row = np.clip(np.floor(np.nan_to_num(v)), 0, pairs.size[:, 1] - 1).astype(np.int64)
    flat = row * pairs.size[:, 0] + col
    z_b = _map(space, pairs.p_maps[pairs.target, flat], s, t)  # [q]
    bad = (z <= 0) | (z_b <= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(bad, np.inf, np.log(x[:, 2] / z_b))
    c = np.mean((pairs.rgb_src - pairs.rgb_maps[pairs.target, flat]) ** 2, axis=1)
    cost = np.where(bad, 2.0, np.minimum(c / (widen * COLOUR_SIGMA) ** 2, 1.0))
    return np.where(seen, cost, np.nan), g


def _cost(pairs: _Pairs, space: str, s: float, t: float, widen: float = 1.0) -> float:
    cost, _ = _residuals(pairs, space, s, t, widen)
    return float(np.where(np.isfinite(cost), cost, 1.0).mean())


def align_views(views: list[View], kind: str, *, seed: int = 0) -> Alignment:
    """The map ``(s, t)`` of ``kind`` ("relative" or "inverse") that makes the views
    agree (module docstring). ``residual`` is the median ``|g|`` (relative depth
    disagreement) and ``inlier_fraction`` the share of seen points with ``|g| <
    GEO_SIGMA``, both at the solution; ``n_points`` the points seen."""
    from scipy.optimize import minimize  # imported when used

    if kind not in SPACE:
        raise ValueError(f"the views align a 'relative' or 'inverse' model, got {kind!r} "
                         f"(a metric model needs no alignment)")
    space = SPACE[kind]
    base = check_views(views)
    pairs = _pairs(views, np.random.default_rng(seed))
    p12 = tuple(float(q) for q in np.percentile(pairs.p_src, QUANTILES))
    if not p12[1] > p12[0]:  # the textured pixels share one value (a silhouette on the sky)
        every = np.unique(pairs.p_maps[np.isfinite(pairs.p_maps)])  # each value once
        p12 = tuple(float(q) for q in np.percentile(every, QUANTILES))
    if not p12[1] > p12[0]:
        raise ValueError("the depth model's output is constant over the views, so no map "
                         "to depth can be found; check the model and --depth-kind")

    sign = -1.0 if space == "inverse" else 1.0  # which way depth runs with the output

    def depths(theta) -> tuple[float, float]:
        z1 = float(np.exp(theta[0]))
        return z1, z1 * float(np.exp(sign * abs(theta[1])))

    def cost(theta, widen=1.0) -> float:
        return _cost(pairs, space, *_from_depths(space, p12, depths(theta)),
                     widen)

    log_z = np.log(base) + np.linspace(*np.log(DEPTH_SPAN), GRID[0])
    log_r = np.linspace(0.0, np.log(RATIO_SPAN), GRID[1])
    grid = sorted((cost((a, b), widen), a, b) for widen in (1.0, WIDEN)
                  for a in log_z for b in log_r)
    starts = list(dict.fromkeys((a, b) for _, a, b in grid))[:STARTS]
    best = min((minimize(cost, np.array(ab), method="Nelder-Mead",
                         options={"xatol": 1e-4, "fatol": 1e-6, "maxiter": 200})
                for ab in starts), key=lambda r: r.fun)
    s, t = _from_depths(space, p12, depths(best.x))
    cost_pt, g = _residuals(pairs, space, s, t)
    seen = np.isfinite(cost_pt) & np.isfinite(g)
    return Alignment(s, t, space, float(np.median(np.abs(np.expm1(g[seen])))) if seen.any()
                     else float("nan"),
                     float(np.mean(np.abs(g[seen]) < GEO_SIGMA)) if seen.any() else 0.0,
                     int(seen.sum()))
