"""A drifting odometry: the true poses corrupted by a seeded random walk, as wheel or
visual odometry gives them (each measured motion a little wrong, the errors adding up).

Odometry measures the motion from one frame to the next, each with an independent
error: ``O_0 = Q_0`` (the first pose is given) and ``O_i = O_i-1 (Q_i-1^-1 Q_i) N_i``,
``N_i = se3_exp((e_t, e_r))`` in the camera's own frame with ``e_t ~ N(0, sigma_t^2 I)``
(scene units, per axis) and ``e_r ~ N(0, sigma_r^2 I)`` (the rotation vector, sigma_r
in degrees per axis). So the relative motions ``O_i-1^-1 O_i`` are off from the true
ones by exactly ``N_i`` (the per-frame sigma), and the absolute poses wander as a
random walk (translation error growing about as ``sqrt(i)`` and faster, rotation
errors turning later motions).
"""

from __future__ import annotations

import numpy as np

from vbgs.tracking.se3 import relative, se3_exp

# --drift default: 1 cm and half a degree per frame (the odometry).
DEFAULT_DRIFT = (0.01, 0.5)


def parse_drift(text: str) -> tuple[float, float]:
    """``"SIGMA_T,SIGMA_R"`` (scene units and degrees per frame) -> two floats >= 0."""
    parts = str(text).split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 2 or not all(np.isfinite(v) and v >= 0 for v in values):
        raise ValueError(f"--drift takes SIGMA_T,SIGMA_R (metres and degrees per frame, "
                         f"both >= 0, e.g. 0.01,0.5), got {text!r}")
    return values


def step_noise(n: int, sigma_t: float, sigma_r_deg: float, seed: int) -> np.ndarray:
    """``[n, 6]`` twists ``(e_t, e_r)`` of the per-frame errors (row 0 is zero: the
    first pose is given)."""
    rng = np.random.default_rng([seed, 26])  # 26: this stream's tag, apart from the scene's
    noise = np.zeros((n, 6))
    if n > 1:
        noise[1:, :3] = rng.normal(0.0, sigma_t, (n - 1, 3))
        noise[1:, 3:] = rng.normal(0.0, np.radians(sigma_r_deg), (n - 1, 3))
    return noise


def odometry(poses, sigma_t: float, sigma_r_deg: float, seed: int = 0) -> np.ndarray:
    """Odometry poses ``[n, 4, 4]`` of the true camera-to-world ``poses [n, 4, 4]``
    (module docstring), float64; the same ``seed`` gives the same drift."""
    truth = np.asarray(poses, np.float64)
    if truth.ndim != 3 or truth.shape[1:] != (4, 4):
        raise ValueError(f"odometry needs poses [n, 4, 4], got shape {truth.shape}")
    errors = se3_exp(step_noise(len(truth), sigma_t, sigma_r_deg, seed))
    out = np.empty_like(truth)
    if len(truth):
        out[0] = truth[0]
    for i in range(1, len(truth)):
        out[i] = out[i - 1] @ relative(truth[i - 1], truth[i]) @ errors[i]
    return out
