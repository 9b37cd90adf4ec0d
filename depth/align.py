"""Align relative or inverse depth predictions to metric reference depth.

Given a prediction ``p`` and metric reference depth ``d`` at a sparse set of pixels
(a mask or indices; reference 0 = missing), find ``(s, t)`` in one of two spaces:

- ``space="depth"``:   ``d_hat = s * p + t``
- ``space="inverse"``: ``1 / d_hat = s * p + t``  (``d_hat = 1 / (s p + t)``)

Methods:

- ``median``: shift 0 and ``s = median_i(y_i / p_i)`` with ``y = d`` (depth space) or
  ``y = 1/d`` (inverse space): the minimiser of ``sum_i |log s + log p_i - log y_i|``.
- ``scale-shift`` / ``scale-shift-inverse``: robust least squares in depth /
  inverse-depth space,
  ``min_{s,t} sum_i rho((s p_i + t - y_i) / sigma)``, with ``rho`` Tukey's biweight
  (``c = 4.685``) and ``sigma = 1.4826 * median_i |r_i|`` re-estimated each step.
  It starts from the least-median-of-squares fit among seeded random 2-point fits
  (breakdown 50%), then runs iteratively reweighted least squares, each step
  ``min sum_i w_i (s p_i + t - y_i)^2`` with ``w_i = (1 - (r_i / c sigma)^2)^2``
  for ``|r_i| < c sigma`` and 0 otherwise.

Inliers are points with ``|r_i| < c sigma`` at the solution. ``residual`` is the median
absolute relative depth error ``|d_hat - d| / d`` over the inliers.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

METHODS = ("none", "median", "scale-shift", "scale-shift-inverse")
SPACES = ("depth", "inverse")
DEFAULT_METHOD = {"metric": "none", "relative": "scale-shift", "inverse": "scale-shift-inverse"}

TUKEY_C = 4.685  # 95% efficiency under Gaussian noise
MAD_TO_SIGMA = 1.4826  # sigma = 1.4826 * MAD for Gaussian residuals
SIGMA_FLOOR = 1e-9  # relative to the median |target|; keeps exact data from dividing by 0
LMEDS_SAMPLES = 256  # random 2-point fits tried for the robust start
LMEDS_EVAL_POINTS = 4096  # points used to score each start (subsampled when more)
IRLS_MAX_ITER = 50
IRLS_TOL = 1e-10  # relative change of (s, t) that ends the iterations
MIN_POINTS = {"median": 1, "scale-shift": 3}


class Alignment(NamedTuple):
    """An alignment ``d_hat = s p + t`` (depth) or ``1/d_hat = s p + t`` (inverse)."""

    scale: float
    shift: float
    space: str  # "depth" | "inverse"
    residual: float  # median |d_hat - d| / d over the inliers (nan: no reference)
    inlier_fraction: float
    n_points: int  # reference pixels used


IDENTITY = Alignment(1.0, 0.0, "depth", float("nan"), float("nan"), 0)


def apply(alignment: Alignment, prediction: np.ndarray) -> np.ndarray:
    """Metric depth from a prediction, float32; non-finite or non-positive depth -> 0."""
    p = np.asarray(prediction, np.float64)
    z = alignment.scale * p + alignment.shift
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = 1.0 / z if alignment.space == "inverse" else z
        ok = np.isfinite(depth) & (depth > 0)
    return np.where(ok, depth, 0.0).astype(np.float32)


def select(prediction, reference, mask=None) -> tuple[np.ndarray, np.ndarray]:
    """Paired ``(p, d)`` float64 at the mask's pixels where both are usable.

    ``mask``: None (all pixels), a boolean array shaped like ``prediction``, flat
    integer indices, or a tuple of index arrays (``np.nonzero`` style).
    Pixels with reference depth <= 0 or non-finite values are dropped.
    """
    p = np.asarray(prediction, np.float64)
    d = np.asarray(reference, np.float64)
    if p.shape != d.shape:
        raise ValueError(
            f"prediction {p.shape} and reference depth {d.shape} must have the same shape; "
            "resize the reference to the frame size"
        )
    if mask is None:
        p, d = p.ravel(), d.ravel()
    elif isinstance(mask, tuple):
        p, d = p[mask], d[mask]
    else:
        m = np.asarray(mask)
        if m.dtype == bool:
            if m.shape != p.shape:
                raise ValueError(f"boolean mask {m.shape} must match the prediction {p.shape}")
            p, d = p[m], d[m]
        elif np.issubdtype(m.dtype, np.integer):
            p, d = p.ravel()[m.ravel()], d.ravel()[m.ravel()]
        else:
            raise ValueError(f"mask must be boolean or integer indices, got dtype {m.dtype}")
    keep = np.isfinite(p) & np.isfinite(d) & (d > 0)
    return p[keep], d[keep]


def _target(d: np.ndarray, space: str) -> np.ndarray:
    if space not in SPACES:
        raise ValueError(f"space must be one of {SPACES}, got {space!r}")
    return 1.0 / d if space == "inverse" else d


def _need(n: int, at_least: int) -> None:
    if n < at_least:
        raise ValueError(
            f"only {n} usable reference pixels (need {at_least}); make sure the mask covers "
            "pixels with reference depth > 0 and finite predictions"
        )


def _robust_sigma(r: np.ndarray, y: np.ndarray) -> float:
    floor = SIGMA_FLOOR * max(float(np.median(np.abs(y))), np.finfo(float).tiny)
    return max(MAD_TO_SIGMA * float(np.median(np.abs(r))), floor)


def _summary(scale, shift, space, p, d, r, y) -> Alignment:
    inlier = np.abs(r) < TUKEY_C * _robust_sigma(r, y)
    a = Alignment(float(scale), float(shift), space, float("nan"), float(inlier.mean()), len(p))
    if inlier.any():
        rel = np.abs(apply(a, p[inlier]).astype(np.float64) - d[inlier]) / d[inlier]
        a = a._replace(residual=float(np.median(rel)))
    return a


def median_scale(prediction, reference, mask=None, *, space: str = "depth") -> Alignment:
    """Scale only: ``s = median_i(y_i / p_i)`` over pixels with ``p_i > 0``
    (``y = d`` or ``1/d``); ``t = 0``. Inliers from the log-ratio residual.
    """
    p, d = select(prediction, reference, mask)
    pos = p > 0
    p, d = p[pos], d[pos]
    _need(len(p), MIN_POINTS["median"])
    y = _target(d, space)
    scale = float(np.median(y / p))
    log_r = np.log(scale * p) - np.log(y)
    return _summary(scale, 0.0, space, p, d, log_r, np.ones(1))


def _weighted_line(x, y, w) -> tuple[float, float]:
    """``argmin_{s,t} sum w (s x + t - y)^2``: ``s = cov_w(x, y) / var_w(x)``,
    ``t = mean_w(y) - s mean_w(x)``."""
    sw = w.sum()
    if sw <= 0:
        raise ValueError("robust fit lost all its points (every weight is 0)")
    mx, my = (w * x).sum() / sw, (w * y).sum() / sw
    var = (w * (x - mx) ** 2).sum()
    if var <= 0:
        raise ValueError(
            "the prediction is constant over the reference pixels, so scale and shift are "
            "not identifiable; use more or more varied reference pixels, or method='median'"
        )
    s = (w * (x - mx) * (y - my)).sum() / var
    return float(s), float(my - s * mx)


def _lmeds_start(x, y, rng) -> tuple[float, float]:
    """Least-median-of-squares line among random 2-point fits (and the plain LS fit)."""
    n = len(x)
    sub = rng.choice(n, LMEDS_EVAL_POINTS, replace=False) if n > LMEDS_EVAL_POINTS else slice(None)
    xs, ys = x[sub], y[sub]
    i, j = rng.integers(0, n, LMEDS_SAMPLES), rng.integers(0, n, LMEDS_SAMPLES)
    dx = x[j] - x[i]
    ok = np.abs(dx) > 0
    s = np.append((y[j] - y[i])[ok] / dx[ok], 0.0)
    t = np.append(y[i][ok] - s[:-1] * x[i][ok], 0.0)
    s[-1], t[-1] = _weighted_line(x, y, np.ones_like(x))
    med = np.median((s[:, None] * xs[None, :] + t[:, None] - ys[None, :]) ** 2, axis=1)
    best = int(np.argmin(med))
    return float(s[best]), float(t[best])


def scale_shift(prediction, reference, mask=None, *, space: str = "depth",
                seed: int = 0) -> Alignment:
    """Robust least-squares scale and shift in depth (or inverse-depth) space.

    Minimises ``sum_i rho((s p_i + t - y_i) / sigma)`` (Tukey) by IRLS from a
    least-median-of-squares start; deterministic for a given ``seed``.
    """
    p, d = select(prediction, reference, mask)
    _need(len(p), MIN_POINTS["scale-shift"])
    y = _target(d, space)
    s, t = _lmeds_start(p, y, np.random.default_rng(seed))
    for _ in range(IRLS_MAX_ITER):
        r = s * p + t - y
        u = r / (TUKEY_C * _robust_sigma(r, y))
        w = np.where(np.abs(u) < 1.0, (1.0 - u**2) ** 2, 0.0)
        s_new, t_new = _weighted_line(p, y, w)
        change = abs(s_new - s) + abs(t_new - t)
        s, t = s_new, t_new
        if change <= IRLS_TOL * (abs(s) + abs(t)):
            break
    return _summary(s, t, space, p, d, s * p + t - y, y)


def scale_shift_inverse(prediction, reference, mask=None, *, seed: int = 0) -> Alignment:
    """:func:`scale_shift` in inverse-depth space: ``1 / d_hat = s p + t``."""
    return scale_shift(prediction, reference, mask, space="inverse", seed=seed)


def align(prediction, reference, mask=None, method: str = "scale-shift", *,
          space: str | None = None, seed: int = 0) -> Alignment:
    """One entry for every method in :data:`METHODS`.

    ``space`` applies to ``median`` only (default "depth"; "inverse" for disparity
    predictions). ``none`` returns the identity, scored against the reference.
    """
    if method == "median":
        return median_scale(prediction, reference, mask, space=space or "depth")
    if method == "scale-shift":
        return scale_shift(prediction, reference, mask, space="depth", seed=seed)
    if method == "scale-shift-inverse":
        return scale_shift_inverse(prediction, reference, mask, seed=seed)
    if method == "none":
        p, d = select(prediction, reference, mask)
        if len(p) == 0:
            return IDENTITY
        return _summary(1.0, 0.0, "depth", p, d, np.log(np.maximum(p, 1e-12) / d), np.ones(1))
    raise ValueError(f"unknown alignment method {method!r}; choose one of {METHODS}")
