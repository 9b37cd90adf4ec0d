import numpy as np
import pytest

from vbgs.render.camera import (
    Camera,
    from_fov,
    look_at,
    opengl_to_opencv,
    pixel_grid,
    project,
    rigid,
    unproject,
    valid_depth,
)
from vbgs.render.pixels import pixel_centres


def _camera(width=20, height=14):
    pose = look_at([1.5, -2.0, 0.7], [0.1, 0.2, 0.3])
    return Camera(18.0, 17.0, 9.7, 7.4, width, height, pose)


def test_look_at_is_a_rigid_pose_facing_the_target():
    eye, target = np.array([1.5, -2.0, 0.7]), np.array([0.1, 0.2, 0.3])
    pose = look_at(eye, target)
    rot = pose[:3, :3]
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0)
    forward = (target - eye) / np.linalg.norm(target - eye)
    np.testing.assert_allclose(rot[:, 2], forward, atol=1e-12)
    assert rot[2, 1] < 0  # image y (down) points against world z (up)


def test_from_fov_focal_length():
    cam = from_fov(64, 48, np.deg2rad(90.0), np.eye(4))
    assert cam.fx == pytest.approx(32.0)
    assert (cam.cx, cam.cy) == (32.0, 24.0)


def test_unproject_project_round_trip():
    cam = _camera()
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 4.0, (cam.height, cam.width)).astype(np.float32)
    rgb = rng.uniform(0, 1, (cam.height, cam.width, 3)).astype(np.float32)
    xyz, colours = unproject(cam, rgb, depth)
    assert xyz.shape == (cam.height * cam.width, 3) and xyz.dtype == np.float32
    uv, z = project(cam, xyz)
    u, v = pixel_grid(cam)
    np.testing.assert_allclose(uv[:, 0], u.ravel(), atol=2e-4)
    np.testing.assert_allclose(uv[:, 1], v.ravel(), atol=2e-4)
    np.testing.assert_allclose(z, depth.ravel(), rtol=1e-6)
    np.testing.assert_array_equal(colours, rgb.reshape(-1, 3))


def test_pixel_centres_and_principal_point():
    cam = Camera(10.0, 10.0, 2.0, 1.5, 4, 3, np.eye(4))
    u, v = pixel_grid(cam)
    assert u[0, 0] == 0.5 and v[0, 0] == 0.5 and u[-1, -1] == 3.5 and v[-1, -1] == 2.5
    uv, z = project(cam, np.array([[0.0, 0.0, 2.0]]))
    np.testing.assert_allclose(uv, [[2.0, 1.5]])
    assert z[0] == 2.0


def test_every_pixel_grid_uses_the_one_centre_convention():
    """camera.pixel_grid, pixels.pixel_centres and the rasterizer's tile pixels agree."""
    from vbgs.render.composite import tile_pixel_coords

    h, w, tile = 6, 8, 4
    uv = pixel_centres(h, w)  # [h * w, 2]
    np.testing.assert_array_equal(uv[:3], [[0.5, 0.5], [1.5, 0.5], [2.5, 0.5]])
    u, v = pixel_grid(Camera(1.0, 1.0, 0.0, 0.0, w, h, np.eye(4)))
    np.testing.assert_array_equal(np.stack([u, v], -1).reshape(-1, 2), uv)
    n_tiles_x = w // tile
    for tile_id in range(n_tiles_x * 2):
        got = np.stack([np.asarray(a) for a in tile_pixel_coords(tile_id, n_tiles_x, tile)], -1)
        ty, tx = divmod(tile_id, n_tiles_x)
        want = uv.reshape(h, w, 2)[ty * tile:(ty + 1) * tile, tx * tile:(tx + 1) * tile]
        valid = (got[:, 1] < h)  # the last tile row reaches past the image
        np.testing.assert_array_equal(got[valid], want.reshape(-1, 2)[: valid.sum()])


def test_opengl_to_opencv_flips_y_and_z_axes():
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    pose_gl = np.eye(4)
    pose_gl[:3, :3], pose_gl[:3, 3] = q, [0.3, -1.0, 2.0]
    pose_cv = opengl_to_opencv(pose_gl)
    np.testing.assert_allclose(pose_cv[:3, 0], pose_gl[:3, 0])
    np.testing.assert_allclose(pose_cv[:3, 1], -pose_gl[:3, 1])
    np.testing.assert_allclose(pose_cv[:3, 2], -pose_gl[:3, 2])
    np.testing.assert_allclose(pose_cv[:3, 3], pose_gl[:3, 3])
    np.testing.assert_allclose(opengl_to_opencv(pose_cv), pose_gl)  # its own inverse
    # an OpenGL camera looks down its -z axis: a point there is in front of the CV camera
    point = pose_gl[:3, 3] - 2.5 * pose_gl[:3, 2] + 0.4 * pose_gl[:3, 1]  # above the centre
    cam = Camera(50.0, 50.0, 16.0, 12.0, 32, 24, pose_cv)
    uv, z = project(cam, point[None])
    assert z[0] == pytest.approx(2.5)
    assert uv[0, 0] == pytest.approx(16.0)
    assert uv[0, 1] == pytest.approx(12.0 - 50.0 * 0.4 / 2.5)  # up in the world = up in the image


def test_invalid_depth_is_skipped():
    cam = _camera(5, 2)
    depth = np.array([[0.0, np.nan, np.inf, -1.0, 2.0], [9.0, 1.0, 1.5, 0.5, 3.0]], np.float32)
    rgb = np.arange(30, dtype=np.float32).reshape(2, 5, 3) / 30
    mask = valid_depth(depth, max_depth=5.0)
    expected = np.array([[0, 0, 0, 0, 1], [0, 1, 1, 1, 1]], bool)
    np.testing.assert_array_equal(mask, expected)
    xyz, colours = unproject(cam, rgb, depth, max_depth=5.0)
    assert len(xyz) == 5
    np.testing.assert_array_equal(colours, rgb[expected])
    _, z = project(cam, xyz)
    np.testing.assert_allclose(z, depth[expected], rtol=1e-6)
    assert np.all(np.isfinite(xyz))
    assert len(unproject(cam, rgb, depth)[0]) == 6  # 9.0 is valid without max_depth


@pytest.mark.parametrize(
    "rgb_shape, depth_shape", [((14, 20), (14, 20)), ((14, 20, 3), (20, 14)), ((7, 20, 3), (7, 20))]
)
def test_shape_errors(rgb_shape, depth_shape):
    cam = _camera()
    with pytest.raises(ValueError, match="expected rgb"):
        unproject(cam, np.zeros(rgb_shape, np.float32), np.ones(depth_shape, np.float32))


def test_camera_is_a_pytree_with_static_size():
    """Intrinsics and pose are leaves; width and height are static: a jitted function
    takes the camera as one argument, keeps the sizes as ints, and compiles once per size."""
    import jax
    import jax.numpy as jnp

    cam = _camera()
    leaves = jax.tree_util.tree_leaves(cam)
    assert len(leaves) == 5 and leaves[-1].shape == (4, 4)

    @jax.jit
    def centre_ray(c):
        assert isinstance(c.width, int) and isinstance(c.height, int)
        return jnp.stack([(c.width / 2 - c.cx) / c.fx, (c.height / 2 - c.cy) / c.fy])

    np.testing.assert_allclose(centre_ray(cam), [(10 - 9.7) / 18.0, (7 - 7.4) / 17.0], rtol=1e-5)
    centre_ray(cam._replace(fx=20.0, pose=np.eye(4)))  # new values: no new compile
    assert centre_ray._cache_size() == 1
    centre_ray(_camera(width=22))
    assert centre_ray._cache_size() == 2
    doubled = jax.tree_util.tree_map(lambda a: 2 * a, cam)
    assert (doubled.fx, doubled.width, doubled.height) == (36.0, cam.width, cam.height)


def test_rigid_equals_the_matrix_product():
    """camera.rigid (one column of R at a time) against NumPy's ``p @ R.T + t``: equal to
    float64 rounding, and equal in float32 (what unproject returns)."""
    rng = np.random.default_rng(0)
    pose = look_at((1.3, -2.0, 0.7), (0.1, 0.2, 0.3))
    p = rng.normal(size=(5000, 3)) * 3.0
    slow = p @ pose[:3, :3].T + pose[:3, 3]
    fast = rigid(p, pose)
    np.testing.assert_allclose(fast, slow, rtol=1e-14, atol=1e-14)
    assert (fast.astype(np.float32) != slow.astype(np.float32)).mean() < 1e-3


def test_unproject_equals_the_rays_times_depth_turned_by_the_pose():
    """unproject (blocks of pixels, a column at a time) against the direct formula,
    ``rigid(camera_rays[mask] * z)`` in float64 rounded to float32: equal to the bit on a
    frame of more than one block; depth_points and camera_rays against pixel_rays."""
    from vbgs.render.camera import BLOCK, camera_rays, depth_points
    from vbgs.render.pixels import pixel_rays

    rng = np.random.default_rng(0)
    cam = Camera(150.3, 149.1, 101.7, 77.9, 200, 160, look_at([1.5, -2.0, 0.7], [0.1, 0.2, 0.3]))
    depth = rng.uniform(0.5, 6.0, (160, 200)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.3] = 0.0
    rgb = rng.random((160, 200, 3)).astype(np.float32)
    mask = valid_depth(depth)
    assert mask.sum() > 2 * BLOCK
    rays = pixel_rays(160, 200, cam.fx, cam.fy, cam.cx, cam.cy)
    np.testing.assert_array_equal(camera_rays(cam), rays)
    points = rays[mask] * depth[mask].astype(np.float64)[:, None]
    np.testing.assert_array_equal(depth_points(cam, depth), points)
    xyz, colours = unproject(cam, rgb, depth)
    assert xyz.dtype == colours.dtype == np.float32
    np.testing.assert_array_equal(xyz, rigid(points, cam.pose).astype(np.float32))
    np.testing.assert_array_equal(colours, rgb[mask])
