"""Splats: PLY round trip, covariance <-> (scale, rotation), pruning."""

import jax.numpy as jnp
import numpy as np
import pytest
from plyfile import PlyData

from vbgs.render.splats import (
    MIN_SCALE,
    SH_C0,
    Splats,
    covs_from_scale_rotation,
    load_ply,
    prune,
    rotations_from_quaternions,
    save_ply,
    scale_rotation_from_covs,
)


def random_covs(rng, k):
    scales = np.exp(rng.normal(-3, 1, (k, 3)))
    return np.asarray(covs_from_scale_rotation(jnp.asarray(scales), jnp.asarray(rng.normal(size=(k, 4)))))


def degenerate_covs(rng):
    """Planar (one zero axis), linear (two), isotropic and exactly zero covariances."""
    rot = np.asarray(rotations_from_quaternions(jnp.asarray(rng.normal(size=(3, 4)))), np.float64)
    planar = rot[0] @ np.diag([0.04, 0.01, 0.0]) @ rot[0].T
    line = rot[1] @ np.diag([0.0, 0.09, 0.0]) @ rot[1].T
    return np.stack([planar, line, 0.02 * np.eye(3), np.zeros((3, 3)), np.diag([0.0, 0.0, 0.01])])


def assert_covs_close(actual, expected):
    """Equal to float32 precision relative to each covariance's size, up to the MIN_SCALE floor."""
    actual, expected = np.asarray(actual, np.float64), np.asarray(expected, np.float64)
    size = np.abs(expected).max(axis=(1, 2), keepdims=True)
    assert np.all(np.abs(actual - expected) < 1e-5 * size + 2 * MIN_SCALE**2)


def random_splats(seed=0, k=50):
    rng = np.random.default_rng(seed)
    covs = np.concatenate([random_covs(rng, k - 5), degenerate_covs(rng)])
    return Splats(
        jnp.asarray(rng.normal(size=(k, 3)), jnp.float32), jnp.asarray(covs, jnp.float32),
        jnp.asarray(rng.uniform(size=(k, 3)), jnp.float32),
        jnp.asarray(rng.uniform(0.01, 0.99, k), jnp.float32),
    )


def test_scale_rotation_round_trip_including_degenerate():
    rng = np.random.default_rng(1)
    covs = np.concatenate([random_covs(rng, 200), degenerate_covs(rng)])
    scales, quats = scale_rotation_from_covs(covs)
    np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-12)
    assert np.all(quats[:, 0] >= 0) and np.all(scales >= MIN_SCALE)
    rots = np.asarray(rotations_from_quaternions(jnp.asarray(quats, jnp.float32)), np.float64)
    np.testing.assert_allclose(np.linalg.det(rots), 1.0, atol=1e-5)
    rebuilt = np.asarray(covs_from_scale_rotation(jnp.asarray(scales, jnp.float32),
                                                  jnp.asarray(quats, jnp.float32)))
    assert_covs_close(rebuilt, covs)
    # Zero axes of degenerate covariances are floored, not -inf or NaN.
    np.testing.assert_allclose(np.sort(scales[[-5, -4, -2, -1]], axis=1)[:, 0], MIN_SCALE)
    np.testing.assert_allclose(scales[-3], np.sqrt(0.02), rtol=1e-6)  # isotropic
    np.testing.assert_allclose(np.sort(scales[-5]), [MIN_SCALE, 0.1, 0.2], rtol=1e-6)


def test_quaternions_of_known_rotations():
    half_turn_z = np.diag([-1.0, -1.0, 1.0])
    _, quats = scale_rotation_from_covs(half_turn_z @ np.diag([1.0, 4.0, 9.0]) @ half_turn_z.T
                                        [None])
    rot = np.asarray(rotations_from_quaternions(jnp.asarray(quats)))[0]
    # eigh orders the axes by variance, so the rotation maps e_i to the i-th smallest axis.
    np.testing.assert_allclose(np.abs(rot), np.eye(3), atol=1e-6)
    np.testing.assert_allclose(
        np.asarray(rotations_from_quaternions(jnp.asarray([[0.0, 0.0, 0.0, 2.0]])))[0],
        half_turn_z, atol=1e-7)


def test_ply_round_trip(tmp_path):
    splats = random_splats()
    path = tmp_path / "splats.ply"
    save_ply(path, splats)
    loaded = load_ply(path)
    for name in ("means", "colours", "opacities"):
        np.testing.assert_allclose(getattr(loaded, name), getattr(splats, name), atol=2e-7,
                                   err_msg=name)
    assert_covs_close(loaded.covs, splats.covs)
    assert all(a.dtype == jnp.float32 for a in loaded)


def test_an_interrupted_ply_write_leaves_the_earlier_file(tmp_path, monkeypatch):
    """save_ply writes beside the file and renames: Ctrl-C mid-write changes nothing."""
    path = tmp_path / "splats.ply"
    save_ply(path, random_splats())
    before = path.read_bytes()

    def half_then_interrupt(self, stream):
        with open(stream, "wb") as f:
            f.write(b"ply\nformat binary_little_endian 1.0\n")
        raise KeyboardInterrupt

    monkeypatch.setattr(PlyData, "write", half_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        save_ply(path, random_splats())
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["splats.ply"]  # no temporary left


def test_ply_uses_the_3dgs_layout(tmp_path):
    splats = random_splats(k=8)
    path = tmp_path / "splats.ply"
    save_ply(path, splats)
    vertex = PlyData.read(str(path))["vertex"]
    names = [p.name for p in vertex.properties]
    assert names == ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                     "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    np.testing.assert_allclose(vertex["f_dc_1"], (np.asarray(splats.colours[:, 1]) - 0.5) / SH_C0,
                               rtol=1e-6)
    o = np.asarray(splats.opacities, np.float64)
    np.testing.assert_allclose(vertex["opacity"], np.log(o / (1 - o)), rtol=1e-5)
    assert np.all(vertex["nx"] == 0)


def test_load_ply_reports_missing_properties(tmp_path):
    from plyfile import PlyElement

    path = tmp_path / "points.ply"
    points = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    PlyData([PlyElement.describe(points, "vertex")]).write(str(path))
    with pytest.raises(ValueError, match="missing vertex properties"):
        load_ply(path)


def test_prune():
    splats = random_splats(k=20)
    keep = np.arange(20) % 3 == 0
    kept = prune(splats, keep)
    assert kept.count == 7
    for a, b in zip(kept, splats, strict=True):
        np.testing.assert_array_equal(a, np.asarray(b)[keep])
    with pytest.raises(ValueError, match="boolean array of shape"):
        prune(splats, np.arange(20) % 3)
    with pytest.raises(ValueError, match="boolean array of shape"):
        prune(splats, keep[:10])
