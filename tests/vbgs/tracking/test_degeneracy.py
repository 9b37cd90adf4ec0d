"""vbgs.tracking.degeneracy through the registration: a map of one textured plane
leaves the motions along it free (said in words, sigma infinite there), a box's corner
fixes every direction; the fusion takes the free directions from another estimate."""

import jax
import numpy as np
import pytest

from vbgs import mapping
from vbgs.tracking import degeneracy, register, se3

CONFIG = register.TrackConfig(levels=(512, 512), inflate=(1.0, 0.0), passes=(2, 2))


def registered(pose, frame):
    """The frame registered, from its true pose, against a map learned from it."""
    config = mapping.Config(components=400)
    state = mapping.init(config, key=jax.random.key(0))
    state, _ = mapping.update(state, frame, config)
    target = register.target(state.mixture.posterior, state.mixture.prior)
    return register.register(target, frame.camera, frame.depth, pose, CONFIG, rgb=frame.rgb)


@pytest.fixture(scope="module")
def plane_found(street):
    return registered(*street)


def test_a_plane_leaves_motions_along_it_free(plane_found):
    free = plane_found.free
    # measured: the 3 smallest scaled eigenvalues under RATIO, the others above it
    print("plane:", free.values)
    assert free.free.shape[1] >= 2 and free.planar
    assert "planar geometry" in free.reason
    words = degeneracy.describe(free.free)
    print(words)
    assert "translation along" in words
    # honest: no finite sigma along what the depth does not fix
    assert not np.all(np.isfinite(plane_found.sigma_t))


def test_a_box_corner_fixes_every_direction(corner):
    found = registered(*corner)
    print("corner:", found.free.values)
    assert found.free.free.shape[1] == 0 and found.free.reason == ""
    assert np.all(np.isfinite(found.sigma_t)) and np.all(found.sigma_t < 1e-2)


def test_fuse_takes_the_free_directions_from_the_other(plane_found, street):
    pose, _ = street
    free = plane_found.free
    other = pose @ se3.se3_exp(np.array([0.01, 0.02, 0.03, 0.001, 0.002, 0.003]))
    h_other = np.eye(6) * 1e6
    fused, cov = degeneracy.fuse(pose, plane_found.hessian, free, other, h_other)
    # along the free directions the pose moved to the other's, along the fixed ones not
    s = np.diag([1, 1, 1, 1 / free.length, 1 / free.length, 1 / free.length])
    off = np.linalg.solve(s, se3.se3_log(se3.relative(pose, other)))
    moved = np.linalg.solve(s, se3.se3_log(se3.relative(pose, fused)))
    np.testing.assert_allclose(free.free.T @ moved, free.free.T @ off, atol=1e-6)
    np.testing.assert_allclose(free.fixed.T @ moved, 0.0, atol=1e-6)
    assert np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0)
    # without the other's information: infinite along them
    _, loose = degeneracy.fuse(pose, plane_found.hessian, free)
    assert not np.all(np.isfinite(np.diag(loose)))


def test_too_few_matched_points_free_everything():
    dirs = degeneracy.directions(np.eye(6), np.ones((10, 3)), matched=3, min_matched=24)
    assert dirs.free.shape[1] == 6 and "only 3" in dirs.reason
