"""Pinhole cameras and the RGB-D <-> coloured point conversions.

Conventions (OpenCV, used everywhere inside the library):

* camera axes: x right, y down, z forward (depth is the z coordinate, not the
  ray length);
* ``pose`` is camera-to-world, a 4x4 rigid transform: ``x_world = R x_cam + t``;
* pixel ``(row, col)`` has its centre at image coordinates
  ``(u, v) = (col + 0.5, row + 0.5)``, so with ``cx = width / 2`` the optical
  axis passes through the middle of the image.

Loaders that read OpenGL/Blender poses (x right, y up, z backward) convert them
with :func:`opengl_to_opencv` at the boundary.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np

from vbgs.render.pixels import pixel_centres, pixel_rays

# Flip of the y and z camera axes: OpenGL/Blender camera frame <-> OpenCV frame.
_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


class Camera(NamedTuple):
    """A pinhole camera.

    fx, fy, cx, cy: intrinsics in pixels; width, height: image size in pixels;
    pose: ``[4, 4]`` camera-to-world transform (OpenCV axes).

    A JAX pytree whose leaves are the intrinsics and the pose; ``width`` and
    ``height`` are static (part of the tree's structure), so a camera passes through
    ``jax.jit`` as one argument and a jitted function compiles once per image size.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    pose: np.ndarray  # [4, 4]

    @property
    def world_to_camera(self) -> np.ndarray:
        """Inverse of the rigid ``pose``, ``[4, 4]``."""
        rot, t = self.pose[:3, :3], self.pose[:3, 3]
        out = np.eye(4, dtype=self.pose.dtype)
        out[:3, :3] = rot.T
        out[:3, 3] = -rot.T @ t
        return out

    @property
    def intrinsics(self) -> np.ndarray:
        """The ``[3, 3]`` calibration matrix K."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], np.float64
        )

    @property
    def position(self) -> np.ndarray:
        """Camera centre in world coordinates, ``[3]``."""
        return self.pose[:3, 3]


def _camera_children(cam: Camera):
    keys = ("fx", "fy", "cx", "cy", "pose")
    return tuple((jax.tree_util.GetAttrKey(k), getattr(cam, k)) for k in keys), (cam.width, cam.height)


def _camera_from_children(sizes, children) -> Camera:
    fx, fy, cx, cy, pose = children
    return Camera(fx, fy, cx, cy, *sizes, pose)


jax.tree_util.register_pytree_with_keys(Camera, _camera_children, _camera_from_children)


def from_fov(width: int, height: int, fov_x: float, pose: np.ndarray) -> Camera:
    """A camera with square pixels and horizontal field of view ``fov_x`` (radians)."""
    f = 0.5 * width / np.tan(0.5 * fov_x)
    return Camera(f, f, width / 2.0, height / 2.0, int(width), int(height), np.asarray(pose, float))


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world pose (OpenCV axes) at ``eye`` looking at ``target``.

    ``up`` is the world direction that should appear upwards in the image.
    """
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:  # looking along `up`: pick any perpendicular
        x = np.cross(z, np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, eye
    return pose


def opengl_to_opencv(pose_gl: np.ndarray) -> np.ndarray:
    """Convert a camera-to-world pose with OpenGL/Blender camera axes to OpenCV axes."""
    return np.asarray(pose_gl, np.float64) @ _GL_TO_CV


def pixel_grid(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Image coordinates ``u, v`` of every pixel centre, each ``[height, width]`` float64."""
    uv = pixel_centres(camera.height, camera.width, np.float64).reshape(camera.height, camera.width, 2)
    return uv[..., 0], uv[..., 1]


def camera_rays(camera: Camera) -> np.ndarray:
    """``[height, width, 3]``: each pixel's ray in the camera frame at unit camera depth
    (:func:`vbgs.render.pixels.pixel_rays`), laid out from its columns' and rows' slopes
    (:func:`ray_slopes`)."""
    x, y = ray_slopes(camera)
    out = np.empty((camera.height, camera.width, 3), np.float64)
    out[..., 0], out[..., 1], out[..., 2] = x, y[:, None], 1.0
    return out


def ray_slopes(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """``x [width]``, ``y [height]`` float64: the rays' camera-frame x of each column and y
    of each row at unit depth (a ray is ``(x[col], y[row], 1)``), read off
    :func:`vbgs.render.pixels.pixel_rays` of one row and one column."""
    h, w = int(camera.height), int(camera.width)
    x = pixel_rays(1, w, camera.fx, camera.fy, camera.cx, camera.cy)[0, :, 0]
    y = pixel_rays(h, 1, camera.fx, camera.fy, camera.cx, camera.cy)[:, 0, 1]
    return x, y


# Pixels a block of the per-pixel float64 work (unproject; the rays and footprints of
# vbgs.mapping.measurement): a block's temporaries (64 kB each) are reused by the
# allocator and stay in the cache, where whole-frame ones (2 MB each at 640 x 480) are
# fresh pages every time, which cost more than the arithmetic (on this project's 2-core
# machine a 2 MB array first touched took 1.7 ms, against 0.1 ms to fill it again).
BLOCK = 8192


def pixel_blocks(n: int):
    """Slices of ``range(n)`` of :data:`BLOCK` items, in order."""
    return (slice(s, min(s + BLOCK, n)) for s in range(0, n, BLOCK))


def block_rays(flat_depth: np.ndarray, pixel: np.ndarray, width: int, slopes
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``z [k]`` (float64), ``x [k]``, ``y [k]``: the depth in ``flat_depth [h * w]`` at the
    pixels ``pixel [k]`` and their rays ``(x, y, 1)`` at unit depth, from ``slopes``
    (:func:`ray_slopes`)."""
    row = pixel // width
    return flat_depth[pixel].astype(np.float64), slopes[0][pixel - row * width], slopes[1][row]


def turned_into(out: np.ndarray, pose: np.ndarray, x: np.ndarray, y: np.ndarray,
                 z: np.ndarray, moved: bool = True) -> None:
    """Write into ``out [k, 3]`` (float32) the camera-frame vectors ``(x, y, z)`` (``[k]``
    float64 each) in the world, ``R v + t`` under the 4 x 4 ``pose = [R t]`` (``moved``
    False: ``R v``), summed in float64 as :func:`rigid` sums them (``((x r0 + y r1) +
    z r2) + t``) and rounded once."""
    for j in range(3):
        col = x * pose[j, 0] + y * pose[j, 1] + z * pose[j, 2]
        out[:, j] = col + pose[j, 3] if moved else col


def valid_depth(depth: np.ndarray, max_depth: float = np.inf) -> np.ndarray:
    """Mask of usable depth: finite, strictly positive and not beyond ``max_depth``."""
    depth = np.asarray(depth)
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0) & (depth <= max_depth)


def unproject(
    camera: Camera, rgb: np.ndarray, depth: np.ndarray, max_depth: float = np.inf
) -> tuple[np.ndarray, np.ndarray]:
    """RGB-D frame -> coloured world points, skipping invalid depth.

    rgb: ``[h, w, 3]`` in [0, 1]; depth: ``[h, w]`` z-depth in scene units
    (0, NaN, inf or beyond ``max_depth`` mark missing depth).
    Returns ``xyz [n, 3]`` (world) and ``rgb [n, 3]`` as float32.
    """
    rgb, depth = check_frame(camera, rgb, depth)
    pixel = np.flatnonzero(valid_depth(depth, max_depth))
    return (_world_points(camera, depth, pixel),
            pixel_rows(rgb, pixel).astype(np.float32, copy=False))


def check_frame(camera: Camera, rgb, depth) -> tuple[np.ndarray, np.ndarray]:
    """``rgb [h, w, 3]`` and ``depth [h, w]`` as arrays, refused with what was expected
    when their shapes are not the camera's."""
    rgb, depth = np.asarray(rgb), np.asarray(depth)
    shape = (camera.height, camera.width)
    if rgb.shape != shape + (3,) or depth.shape != shape:
        raise ValueError(
            f"frame shapes rgb {rgb.shape} and depth {depth.shape} do not match the camera "
            f"size {shape}: expected rgb {shape + (3,)} and depth {shape}"
        )
    return rgb, depth


def depth_points(camera: Camera, depth: np.ndarray, max_depth: float = np.inf) -> np.ndarray:
    """Camera-frame points ``[n, 3]`` (float64) of the pixels with valid depth, in
    row-major order (the order :func:`unproject` returns them; the pose is not read)."""
    depth = np.asarray(depth)
    return _points_at(camera, depth, valid_depth(depth, max_depth))


def rigid(points: np.ndarray, pose) -> np.ndarray:
    """``points [n, 3] R^T + t`` for the 4 x 4 ``pose = [R t]`` (NumPy), written out one
    column of ``R`` at a time: NumPy's matmul of an ``[n, 3]`` array by a 3 x 3 matrix
    takes ten times as long (0.12 s against 0.012 s of CPU for a 640 x 480 frame,
    measured); the points come out equal in float32 (checked on the room's frames)."""
    rot, t = np.asarray(pose)[:3, :3], np.asarray(pose)[:3, 3]
    return (points[:, 0:1] * rot[:, 0] + points[:, 1:2] * rot[:, 1]
            + points[:, 2:3] * rot[:, 2] + t)


def _points_at(camera: Camera, depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Camera-frame points ``[n, 3]`` (float64) of the pixels ``mask [h, w]``: each ray
    (:func:`block_rays`) times its depth."""
    pixel = np.flatnonzero(mask)
    z, x, y = block_rays(np.asarray(depth).reshape(-1), pixel, int(camera.width),
                          ray_slopes(camera))
    out = np.empty((len(pixel), 3), np.float64)
    out[:, 0], out[:, 1], out[:, 2] = x * z, y * z, z
    return out


def _world_points(camera: Camera, depth: np.ndarray, pixel: np.ndarray) -> np.ndarray:
    """``[n, 3]`` float32: the world points of the pixels ``pixel [n]`` (``row * width +
    col``) of ``depth [h, w]``, as :func:`rigid` of :func:`_points_at` gives them (the
    same float64 operations, a block of :data:`BLOCK` pixels at a time, one column at a
    time: unproject takes 7.5 ms against 48 at 640 x 480), rounded once to float32."""
    flat, slopes = np.asarray(depth).reshape(-1), ray_slopes(camera)
    pose, width = np.asarray(camera.pose), int(camera.width)
    out = np.empty((len(pixel), 3), np.float32)
    for s in pixel_blocks(len(pixel)):
        z, x, y = block_rays(flat, pixel[s], width, slopes)
        turned_into(out[s], pose, x * z, y * z, z)
    return out


def pixel_rows(image: np.ndarray, pixel: np.ndarray) -> np.ndarray:
    """``image [h, w, c]`` at the pixels ``pixel [n]`` (``row * width + col``): ``[n, c]``,
    its dtype, each pixel's ``c`` values copied as one item (a third of the time of an
    ``[n, c]`` gather at 640 x 480)."""
    image = np.ascontiguousarray(image)
    c = image.shape[-1]
    rows = image.reshape(-1, c).view(np.dtype((np.void, c * image.itemsize)))[:, 0]
    return rows[pixel].view(image.dtype).reshape(-1, c)


def project(camera: Camera, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points ``[n, 3]`` -> image coordinates ``uv [n, 2]`` and z-depth ``[n]``.

    Points behind the camera get ``z <= 0``; their ``uv`` is meaningless.
    """
    w2c = camera.world_to_camera
    x_cam = rigid(np.asarray(xyz, np.float64), w2c)
    z = x_cam[:, 2]
    safe = np.where(np.abs(z) > 1e-12, z, 1e-12)
    uv = np.stack([camera.fx * x_cam[:, 0] / safe + camera.cx, camera.fy * x_cam[:, 1] / safe + camera.cy], -1)
    return uv, z
