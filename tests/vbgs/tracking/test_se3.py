"""vbgs.tracking.se3: exp/log inverse of each other at every angle, in float64 and
float32; the point Jacobian against finite differences; orthonormalise."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.tracking import se3

EXP32, LOG32 = jax.jit(se3.se3_exp), jax.jit(se3.se3_log)  # one compile each, not per op
ANGLES = [0.0, 1e-7, 1e-3, 0.3, 0.499, 0.501, 1.0, 2.4, 2.6, 3.1, np.pi - 1e-6]


def twists(angle, n=4, seed=0):
    xi = np.random.default_rng(seed).normal(size=(n, 6))
    axis = xi[:, 3:] / np.linalg.norm(xi[:, 3:], axis=1, keepdims=True)
    xi[:, 3:] = angle * axis
    return xi


@pytest.mark.parametrize("angle", ANGLES)
def test_exp_log_round_trip(angle):
    xi = twists(angle)
    pose = se3.se3_exp(xi)
    rot = pose[:, :3, :3]
    assert np.abs(rot @ rot.transpose(0, 2, 1) - np.eye(3)).max() < 1e-14
    assert np.abs(se3.se3_log(pose) - xi).max() < 1e-12 * max(1.0, 1.0 / (np.pi - angle + 1e-3))
    # float32 (the tracker's): exp within 4e-7 of float64, log back within 1e-6 (1e-3
    # near pi, where float32 keeps about that much of the axis)
    pose32 = np.asarray(EXP32(jnp.asarray(xi, jnp.float32)))
    assert np.abs(pose32 - pose).max() < 4e-7
    back = np.asarray(LOG32(jnp.asarray(pose, jnp.float32)))
    assert np.abs(back - xi).max() < (1e-3 if angle > 3.0 else 1e-6)


def test_rotation_angle_small_in_float32():
    """atan2, not arccos: float32 resolves a 1e-5 rad rotation (arccos gives 0)."""
    angle = jax.jit(lambda w: se3.rotation_angle(se3.so3_exp(w)))
    assert abs(float(angle(jnp.asarray([[1e-5, 0.0, 0.0]], jnp.float32))[0]) - 1e-5) < 1e-9


def test_point_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    p = rng.normal(size=(5, 3)) * 3.0
    jac = se3.point_jacobian(p)  # [5, 3, 6]
    eps = 1e-6
    for k in range(6):
        step = np.zeros(6)
        step[k] = eps
        plus, minus = se3.se3_exp(step), se3.se3_exp(-step)
        fd = ((p @ plus[:3, :3].T + plus[:3, 3]) - (p @ minus[:3, :3].T + minus[:3, 3])) / (2 * eps)
        assert np.abs(fd - jac[:, :, k]).max() < 1e-8


def test_compose_inverse_relative():
    a, b = se3.se3_exp(twists(0.7, 2, seed=2))
    assert np.abs(se3.compose(a, se3.inverse(a)) - np.eye(4)).max() < 1e-14
    assert np.abs(se3.compose(a, se3.relative(a, b)) - b).max() < 1e-14


def test_orthonormalise_restores_a_rotation():
    pose = se3.se3_exp(twists(1.2, 1)[0])
    bent = pose.copy()
    bent[:3, :3] *= 1.01  # a scale error, as products of float32 rotations accumulate
    bent[:3, 0] += 1e-3
    fixed = se3.orthonormalise(bent)
    rot = fixed[:3, :3]
    assert np.abs(rot @ rot.T - np.eye(3)).max() < 1e-14 and np.linalg.det(rot) > 0
    assert np.abs(rot - pose[:3, :3]).max() < 2e-3  # the nearest rotation: close to the true
    assert np.array_equal(fixed[:3, 3], bent[:3, 3])
