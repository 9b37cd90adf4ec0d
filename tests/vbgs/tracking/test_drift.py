"""vbgs.tracking.drift: a seeded random walk with the asked per-frame sigma."""

import numpy as np
import pytest

from vbgs.tracking import drift, se3


def truth(n):
    steps = np.zeros((n, 6))
    steps[:, 0] = 0.2  # forward 0.2 a frame, turning 3 degrees
    steps[:, 5] = np.radians(3.0)
    poses = [np.eye(4)]
    for xi in steps[1:]:
        poses.append(poses[-1] @ se3.se3_exp(xi))
    return np.stack(poses)


def test_seeded_and_first_pose_given():
    q = truth(20)
    a, b = drift.odometry(q, 0.01, 0.5, seed=3), drift.odometry(q, 0.01, 0.5, seed=3)
    assert np.array_equal(a, b)
    assert not np.allclose(a, drift.odometry(q, 0.01, 0.5, seed=4))
    assert np.array_equal(a[0], q[0])
    assert np.abs(drift.odometry(q, 0.0, 0.0) - q).max() < 1e-12  # no noise: the truth


def test_per_frame_sigma():
    q = truth(1201)
    odo = drift.odometry(q, 0.01, 0.5, seed=0)
    # each measured motion is off from the true one by N_i, whose twist has the sigmas
    off = se3.relative(se3.relative(q[:-1], q[1:]), se3.relative(odo[:-1], odo[1:]))
    xi = se3.se3_log(off)
    assert xi[:, :3].std(0) == pytest.approx([0.01] * 3, rel=0.08)
    assert np.degrees(xi[:, 3:].std(0)) == pytest.approx([0.5] * 3, rel=0.08)
    assert np.abs(xi[:, :3].mean(0)).max() < 4 * 0.01 / np.sqrt(1200)
    # the absolute poses wander: after 1200 frames far more than one step's sigma
    assert np.linalg.norm(odo[-1, :3, 3] - q[-1, :3, 3]) > 1.0


def test_parse_drift():
    assert drift.parse_drift("0.01,0.5") == (0.01, 0.5)
    for bad in ("0.01", "a,b", "-1,0.5", "0.01,0.5,1", "nan,1"):
        with pytest.raises(ValueError, match="SIGMA_T,SIGMA_R"):
            drift.parse_drift(bad)
