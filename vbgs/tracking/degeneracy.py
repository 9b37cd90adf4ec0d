"""Which pose directions a frame's depth leaves free, in words, and the pose and
uncertainty once another measurement fixes them.

A registration's Gauss-Newton Hessian ``H [6, 6]`` (the twist ``(v, w)``: translation
in scene units, rotation in radians, the camera's frame) mixes units; scaled by the
frame's typical depth ``L`` (a rotation of ``w`` moves the frame's points by about
``L |w|``), ``S H S`` with ``S = diag(1, 1, 1, 1/L, 1/L, 1/L)`` holds information per
squared scene unit in every direction. Its eigenvectors whose eigenvalue is under
:data:`RATIO` of the largest are free: the depth barely moves the cost along them (a
plane leaves three: the two translations along it and the rotation about its normal).
The fixed-responsibility Hessian of a mixture still counts the width of the map's
flat components along the surface as information there (a point is scored as if drawn
from its component), which the surface as a whole does not carry: that is why such a
direction's sigma was optimistic (0.4 mm for the walk's forward motion under a Kinect)
and why it is replaced, not kept.

:func:`fuse` keeps the registration in the fixed directions and another estimate (the
direct RGB-D odometry, :mod:`vbgs.tracking.direct`) in the free ones; the covariance
is the registration's inverse Hessian on the fixed subspace and the other estimate's
on the free one (infinite without one).

Float64 on the host (6x6 matrices).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.tracking.se3 import relative, se3_exp, se3_log

# A direction is free when its scaled information is under this share of the largest.
# Chosen on the training streams' registrations (128 px, 20k, 60 frames; not on any
# view's score): under a Kinect the walk's frames (the near road only) have their two
# smallest scaled eigenvalues at 4e-3 and 1e-2 of the largest (the third 0.05), the
# object's at 1e-3 and 3e-3; with exact depth the room's smallest is 0.03-0.04 (one
# frame of 60 under 0.01); in tests/vbgs/tracking a synthetic plane's three smallest
# 4e-4 to 2e-3, a box corner's 0.024. Checked on validation trajectories (seed 1; rule:
# the lowest summed ATE of the nine tracked streams): at 3e-3 the walk's near road is no
# longer found planar under a Kinect and its track drifts to 57 mm, a sum of 126.32 mm
# against the default's 24.10 (results/tuning/tracking/ratio/ against
# results/tuning/tracking/tracking.md's default row); 1e-2 kept.
RATIO = 1e-2
# The frame's depth points lie near one plane when PLANAR of them lie within FLAT of
# their median distance from the camera of one plane (a pole or a kerb beside a road
# leaves the road a plane).
# Chosen on the training frames (128 px): the best plane of 32 holds 0.82-1.0 of the
# walk's points under a Kinect (0.90 at the 10th percentile), 0.64-0.84 with exact depth
# (the facades), 0.41-0.55 of the object's under a Kinect.
FLAT, PLANAR = 0.03, 0.85
# Planes tried (through three of the frame's points each).
TRIES = 32
# Camera axes (OpenCV) in words.
AXES = ("horizontal axis (x)", "vertical axis (y)", "viewing direction (z)")


class Directions(NamedTuple):
    """A registration's free directions."""

    free: np.ndarray  # [6, m] unit vectors in the scaled twist (module docstring)
    fixed: np.ndarray  # [6, 6 - m] the other eigenvectors
    values: np.ndarray  # [6] the scaled eigenvalues over the largest, ascending
    length: float  # L: the frame's typical depth (scene units)
    reason: str  # why they are free, in words ('' when none is)
    planar: bool  # the frame's depth points lie near one plane


def _scaling(length: float) -> np.ndarray:
    return np.diag([1.0, 1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])


def directions(h: np.ndarray, points: np.ndarray, ratio: float = RATIO, *,
               matched: int | None = None, min_matched: int = 0) -> Directions:
    """The free and fixed directions of a Hessian ``h [6, 6]`` of a frame whose depth
    points (camera frame) are ``points [n, 3]`` (module docstring); every direction is
    free when only ``matched < min_matched`` points matched the map."""
    points = np.asarray(points, np.float64)
    length = float(np.median(np.linalg.norm(points, axis=1))) if len(points) else 1.0
    s = _scaling(length)
    hs = s @ np.asarray(h, np.float64) @ s
    values, vectors = np.linalg.eigh(0.5 * (hs + hs.T))
    rel = np.clip(values / max(float(values[-1]), 1e-300), 0.0, None)
    few = matched is not None and matched < min_matched
    free = np.ones(6, bool) if few else rel < ratio
    planar = _planar(points, length)
    reason = ""
    if few:
        reason = f"only {matched} of the frame's points lie on the map"
    elif free.any():
        reason = ("not constrained by the depth (planar geometry)" if planar else
                  f"weakly constrained by the depth (under {ratio:g} of the best-fixed "
                  "direction's information)")
    return Directions(vectors[:, free], vectors[:, ~free], rel, length, reason, planar)


def _planar(points: np.ndarray, length: float) -> bool:
    """Whether :data:`PLANAR` of ``points`` lie within :data:`FLAT` ``length`` of one
    plane: the best of :data:`TRIES` planes through three of them (seeded draws)."""
    if len(points) < 3:
        return False
    i, j, k = np.random.default_rng(26).integers(0, len(points), (TRIES, 3)).T
    normal = np.cross(points[j] - points[i], points[k] - points[i])  # [TRIES, 3]
    size = np.linalg.norm(normal, axis=1)
    ok = size > 0
    if not ok.any():
        return False
    unit = normal[ok] / size[ok, None]
    offset = np.sum(points[i[ok]] * unit, axis=1)  # each plane's distance from the camera
    # each point's height over each plane, one axis at a time: a matmul over the frame's
    # points wakes OpenBLAS's threads, whose spinning after it slowed the learner's next
    # update by some 7 ms a frame on 2 cores (object, 128 px: measured with and without
    # OPENBLAS_NUM_THREADS=1)
    height = sum(points[:, a, None] * unit[:, a] for a in range(3))  # [n, planes]
    near = np.abs(height - offset) < FLAT * length
    return float(near.mean(0).max()) >= PLANAR


def describe(free: np.ndarray) -> str:
    """Words for free directions ``[6, m]`` (scaled twist): each as the camera axis it
    moves along or turns about most ('every direction' for all six); '' for none."""
    if np.shape(free)[1] == 6:
        return "every direction"
    words = []
    for vec in np.asarray(free).T:
        i = int(np.argmax(np.abs(vec)))
        kind = "translation along" if i < 3 else "rotation about"
        words.append(f"{kind} the camera's {AXES[i % 3]}")
    return ", ".join(dict.fromkeys(words))  # one mention each, in order


def fuse(pose: np.ndarray, h: np.ndarray, dirs: Directions, other: np.ndarray | None = None,
         h_other: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The pose ``[4, 4]`` with its free directions (``dirs``, of ``h``) taken from
    ``other`` (None: kept as they are) and the twist's covariance ``[6, 6]`` (module
    docstring): the registration's on the fixed subspace, ``h_other``'s (information
    of ``other``'s right twist) on the free one, infinite there without it."""
    s = _scaling(dirs.length)
    u, v = dirs.fixed, dirs.free
    hs = s @ np.asarray(h, np.float64) @ s
    cov = u @ np.linalg.pinv(u.T @ hs @ u) @ u.T if u.shape[1] else np.zeros((6, 6))
    if v.shape[1] == 0:
        return np.asarray(pose, np.float64), s @ cov @ s
    out = np.asarray(pose, np.float64)
    if other is not None:
        zeta = np.linalg.solve(s, se3_log(relative(out, np.asarray(other, np.float64))))
        out = out @ se3_exp(s @ (v @ (v.T @ zeta)))
    info = None if h_other is None else v.T @ (s @ np.asarray(h_other, np.float64) @ s) @ v
    if info is not None and np.all(np.linalg.eigvalsh(info) > 0):
        return out, s @ (cov + v @ np.linalg.inv(info) @ v.T) @ s
    cov = s @ cov @ s  # nothing fixes the free directions: infinite along them
    loose = np.abs(v).max(1) > 1e-6
    cov[loose, :], cov[:, loose] = np.inf, np.inf
    return out, cov
