"""The ray caster's shortcuts give the bits of the plain computations they replace."""

import numpy as np

from vbgs.data.raycast import (
    TILE,
    _bounding_sphere,
    _rays_near,
    _tile_cones,
    _tile_rows,
    _tiles_near,
    camera_rays,
    cast,
    render,
    sample,
    texture,
    texture_planes,
)
from vbgs.data.synthetic import (
    WALK_FOV_X,
    WALK_SKY,
    _frames,
    make_scene,
    scene_primitives,
    walk_poses,
)
from vbgs.render.camera import BLOCK, pixel_grid


def _camera(name="room", size=(64, 48)):
    return make_scene(name, size=size, n_train=1, n_test=1, n_val=1, samples=1).train[0].camera


def test_camera_rays_blocked_product_equals_one_product():
    """camera_rays rotates its rays a block at a time: the same bits as one matrix
    product over a frame of several blocks."""
    cam = _camera()
    u, v = pixel_grid(cam)
    offsets = (np.arange(3) + 0.5) / 3 - 0.5
    u, v = np.broadcast_arrays(u[:, :, None, None] + offsets,
                               v[:, :, None, None] + offsets[:, None])
    d_cam = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], -1)
    rays = camera_rays(cam, samples=3)
    assert len(rays) > 2 * BLOCK
    np.testing.assert_array_equal(
        rays, d_cam.reshape(-1, 3) @ np.asarray(cam.pose, float)[:3, :3].T)


def test_tiles_near_keeps_every_ray_the_sphere_test_passes():
    """The tile cones drop no ray of _rays_near's, for spheres near and far, in front,
    behind and around the origin, and do drop tiles that look away."""
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(40 * TILE + 17, 3))
    dirs = dirs[np.argsort(np.arctan2(dirs[:, 1], dirs[:, 0]))] * rng.uniform(0.5, 2, (len(dirs), 1))
    dir_sq = np.einsum("ij,ij->i", dirs, dirs)
    cones, origin, dropped = _tile_cones(dirs), np.array([0.3, -0.2, 0.1]), 0
    for _ in range(300):
        lo = origin + rng.normal(size=3) * rng.choice([0.5, 3.0, 30.0])
        sphere = _bounding_sphere((lo, lo + rng.uniform(0, 2) * rng.random(3)))
        near = _rays_near(sphere, origin, dirs, dir_sq)
        kept = np.zeros(len(dirs), bool)
        kept[_tile_rows(_tiles_near(sphere, origin, *cones), len(dirs))] = True
        assert not np.any(near & ~kept)
        dropped += np.sum(~kept)
    assert dropped > 0.3 * 300 * len(dirs)


def test_culled_cast_equals_every_primitive_on_every_ray():
    """cast on a frame of many tiles (some primitives culled on most of them): the
    bits of intersecting every primitive with every ray."""
    for name in ("object", "walk"):
        cam = _camera(name)
        prims, dirs = scene_primitives(name), camera_rays(cam, samples=2)
        best_t, rgb = np.full(len(dirs), np.inf), np.zeros((len(dirs), 3))
        for prim in prims:
            t, uv = prim.hit(cam.position, dirs)
            closer = t < best_t
            best_t[closer] = t[closer]
            rgb[closer] = prim.surface.colour(uv[closer])
        t, colours = cast(prims, cam.position, dirs)
        np.testing.assert_array_equal(t, best_t)
        np.testing.assert_array_equal(colours, rgb)


def test_sample_gather_equals_the_four_texel_formula():
    """sample's channel-major gathers and masked wrap-around: the bits of indexing the
    photo by row and column, for a cached photo and a made-up one of odd sides."""
    uv = np.random.default_rng(1).uniform(-3, 5, (5000, 2))
    odd = np.random.default_rng(2).random((37, 20, 3)).astype(np.float32)
    for tex, planes in ((texture("astronaut"), texture_planes("astronaut")), (odd, None)):
        th, tw = tex.shape[:2]
        x, y = uv[:, 0] * tw - 0.5, uv[:, 1] * th - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        ax, ay = (x - x0)[:, None], (y - y0)[:, None]
        c0, r0 = x0.astype(np.int64) % tw, y0.astype(np.int64) % th
        c1, r1 = (c0 + 1) % tw, (r0 + 1) % th
        top = tex[r0, c0] * (1 - ax) + tex[r0, c1] * ax
        bottom = tex[r1, c0] * (1 - ax) + tex[r1, c1] * ax
        np.testing.assert_array_equal(sample(tex, uv, planes), top * (1 - ay) + bottom * ay)


def test_frames_rendered_in_threads_are_each_pose_rendered_in_turn():
    """_frames renders FRAME_THREADS views at a time: the frames, in the poses' order,
    are those of rendering each pose alone."""
    poses = walk_poses(5, 0)[0]
    frames = _frames(scene_primitives("walk"), poses, (24, 18), WALK_FOV_X, WALK_SKY, 2)
    for frame, pose in zip(frames, poses, strict=True):
        np.testing.assert_array_equal(frame.camera.pose, pose)
        rgb, depth = render(scene_primitives("walk"), frame.camera, WALK_SKY, 2)
        np.testing.assert_array_equal(frame.rgb, rgb)
        np.testing.assert_array_equal(frame.depth, depth)
