"""The ray caster's shortcuts give the bits of the plain computations they replace."""

import numpy as np

from vbgs.data.raycast import camera_rays
from vbgs.data.synthetic import make_scene
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
