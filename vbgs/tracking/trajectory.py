"""Trajectory metrics: absolute trajectory error after the standard rigid alignment,
relative pose error per frame step, per-frame pose errors. NumPy, float64.

* **ATE RMSE** (absolute trajectory error): the estimated camera centres are first
  aligned to the true ones by the rigid motion that minimises the squared distances
  (Horn / Umeyama, :func:`align`; no scale for RGB-D, where depth fixes the scale), then
  ``sqrt(mean |R p_i + t - q_i|^2)``, in scene units.
* **RPE** (relative pose error) per frame step: the error of each estimated motion
  from frame ``i`` to ``i + 1`` against the true one, ``E_i = (Q_i^-1 Q_i+1)^-1
  (P_i^-1 P_i+1)``; its translation (RMSE over the steps, scene units) and rotation
  (RMSE of the angles, degrees). Independent of any alignment.
* **Per-frame errors**: each aligned pose against the true one, translation (scene
  units) and rotation (degrees).

Poses are camera-to-world ``[n, 4, 4]`` (:mod:`vbgs.render.camera`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.tracking.se3 import from_rt, relative, rotation_angle


class Alignment(NamedTuple):
    """The rigid motion ``x -> rot x + t`` taking the estimate onto the truth."""

    rot: np.ndarray  # [3, 3]
    t: np.ndarray  # [3]

    def apply(self, poses: np.ndarray) -> np.ndarray:
        """Poses ``[n, 4, 4]`` moved by the alignment (left-multiplied)."""
        return from_rt(self.rot, self.t) @ poses


class TrajectoryErrors(NamedTuple):
    """The metrics of an estimated trajectory against the true one."""

    ate_rmse: float  # scene units, after alignment
    rpe_trans: float  # scene units per frame step (RMSE)
    rpe_rot_deg: float  # degrees per frame step (RMSE)
    trans: np.ndarray  # [n] per-frame position error after alignment
    rot_deg: np.ndarray  # [n] per-frame rotation error after alignment


def _poses(poses, name: str) -> np.ndarray:
    poses = np.asarray(poses, np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"{name} must be camera-to-world poses [n, 4, 4], got shape "
                         f"{poses.shape}")
    if not np.isfinite(poses).all():
        raise ValueError(f"{name} hold non-finite values: the trajectory cannot be scored")
    return poses


def align(source, target) -> Alignment:
    """The rigid motion minimising ``sum |R s_i + t - q_i|^2`` over points ``source``,
    ``target [n, 3]`` (Umeyama's closed form without scale: the SVD of the cross
    covariance, with the reflection removed). Exact for noise-free point sets that
    differ by a rigid motion and are not all on one line."""
    s, q = np.asarray(source, np.float64), np.asarray(target, np.float64)
    if s.shape != q.shape or s.ndim != 2 or s.shape[1] != 3 or len(s) == 0:
        raise ValueError(f"align needs two point sets [n, 3] of the same shape, got "
                         f"{s.shape} and {q.shape}")
    ms, mq = s.mean(0), q.mean(0)
    u, _, vt = np.linalg.svd((q - mq).T @ (s - ms))
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    rot = u @ flip @ vt
    return Alignment(rot, mq - rot @ ms)


def errors(estimate, truth) -> TrajectoryErrors:
    """ATE RMSE after :func:`align`, RPE per frame step and per-frame errors of the
    estimated poses ``[n, 4, 4]`` against the true ones (module docstring)."""
    est, gt = _poses(estimate, "estimated poses"), _poses(truth, "true poses")
    if est.shape != gt.shape:
        raise ValueError(f"{len(est)} estimated poses against {len(gt)} true ones: "
                         f"give one estimate per frame")
    aligned = align(est[:, :3, 3], gt[:, :3, 3]).apply(est)
    trans = np.linalg.norm(aligned[:, :3, 3] - gt[:, :3, 3], axis=-1)
    rot = np.degrees(rotation_angle(relative(gt, aligned)[:, :3, :3]))
    if len(est) > 1:
        step = relative(relative(gt[:-1], gt[1:]), relative(est[:-1], est[1:]))
        rpe_t = float(np.sqrt(np.mean(np.sum(step[:, :3, 3] ** 2, -1))))
        rpe_r = float(np.sqrt(np.mean(np.degrees(rotation_angle(step[:, :3, :3])) ** 2)))
    else:
        rpe_t = rpe_r = 0.0
    return TrajectoryErrors(float(np.sqrt(np.mean(trans**2))), rpe_t, rpe_r, trans, rot)
