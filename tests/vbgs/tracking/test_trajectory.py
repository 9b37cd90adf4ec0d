"""vbgs.tracking.trajectory: Umeyama's alignment is exact, ATE and RPE are zero for a
trajectory that differs by one rigid motion, and they measure known errors."""

import numpy as np
import pytest

from vbgs.tracking import se3, trajectory


def path(n=20, seed=0):
    rng = np.random.default_rng(seed)
    steps = np.concatenate([rng.normal(0, 0.1, (n, 3)), rng.normal(0, 0.05, (n, 3))], 1)
    poses = [np.eye(4)]
    for xi in steps[1:]:
        poses.append(poses[-1] @ se3.se3_exp(xi))
    return np.stack(poses)


def test_align_recovers_a_rigid_motion_exactly():
    truth = path()
    motion = se3.se3_exp(np.array([0.5, -2.0, 1.0, 0.3, -1.1, 2.0]))
    moved = motion @ truth
    found = trajectory.align(truth[:, :3, 3], moved[:, :3, 3])
    assert np.abs(found.rot - motion[:3, :3]).max() < 1e-12
    assert np.abs(found.t - motion[:3, 3]).max() < 1e-12


def test_ate_and_rpe_are_zero_after_a_rigid_motion():
    truth = path()
    moved = se3.se3_exp(np.array([3.0, 1.0, -2.0, 0.2, 0.4, -2.5])) @ truth
    err = trajectory.errors(moved, truth)
    assert err.ate_rmse < 1e-12 and err.rpe_trans < 1e-12 and err.rpe_rot_deg < 1e-9
    assert err.trans.max() < 1e-12 and err.rot_deg.max() < 1e-9


def test_known_errors():
    truth = path(30)
    # one frame pushed 0.1 along x (camera frame): the alignment moves the others a
    # little, the ATE is about 0.1 / sqrt(30); two RPE steps change by 0.1 each
    est = truth.copy()
    est[10] = est[10] @ se3.se3_exp(np.array([0.1, 0, 0, 0, 0, 0]))
    err = trajectory.errors(est, truth)
    assert err.ate_rmse == pytest.approx(0.1 * np.sqrt(29 / 30) / np.sqrt(30), rel=0.05)
    assert err.rpe_trans == pytest.approx(0.1 * np.sqrt(2 / 29), rel=1e-9)
    assert err.rpe_rot_deg < 1e-9
    # a rotation of one frame by 2 degrees about its own centre
    est = truth.copy()
    est[5] = est[5] @ se3.se3_exp(np.array([0, 0, 0, 0, 0, np.radians(2.0)]))
    err = trajectory.errors(est, truth)
    assert err.ate_rmse < 1e-12  # centres unchanged
    assert err.rot_deg[5] == pytest.approx(2.0, rel=1e-9)
    assert err.rpe_rot_deg == pytest.approx(2.0 * np.sqrt(2 / 29), rel=1e-9)


def test_refuses_bad_input():
    with pytest.raises(ValueError, match="one estimate per frame"):
        trajectory.errors(path(5), path(6))
    with pytest.raises(ValueError, match="non-finite"):
        trajectory.errors(np.full((3, 4, 4), np.nan), path(3))
