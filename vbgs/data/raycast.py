"""Analytic ray casting against textured primitives: exact colour and z-depth.

The synthetic scenes (:mod:`vbgs.data.synthetic`) are lists of primitives. Each
primitive implements

* ``hit(origin [3], dirs [n, 3]) -> (t [n], uv [n, 2])``: ray parameter of the
  nearest intersection with ``t > T_MIN`` (``inf`` on a miss) and the texture
  coordinates there. ``t`` is measured in units of ``dirs``: rays built with a
  camera-frame z component of 1 give ``t`` = z-depth directly;
* ``distance(points [n, 3]) -> [n]``: unsigned Euclidean distance to the surface
  (used by tests to check that depth is exact);
* ``bounds() -> (lo [3], hi [3])``: an axis-aligned box around the surface.

Surfaces are two-sided and unlit: colour is the texture (albedo) at the hit
point, the same from every viewpoint, which is what view-independent splat
colours can represent exactly. Textures are bundled scikit-image photos, resized
once to ``TEXTURE_SIZE`` and sampled bilinearly with wrap-around, so ``uv``
beyond [0, 1) tiles the photo. ``uv = (0, 0)`` is the photo's top-left corner,
``u`` runs along its columns, ``v`` down its rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, cached_property

import numpy as np
from skimage import data as skdata
from skimage.transform import resize

from vbgs.render.camera import Camera, pixel_blocks, pixel_grid

T_MIN = 1e-6  # smallest accepted ray parameter: ignores hits at the ray origin
TEXTURE_SIZE = 256  # textures are resized once to TEXTURE_SIZE x TEXTURE_SIZE
TEXTURES = (
    "astronaut",
    "coffee",
    "chelsea",
    "rocket",
    "camera",
    "brick",
    "grass",
    "gravel",
    "immunohistochemistry",
    "colorwheel",
)


@cache
def texture(name: str) -> np.ndarray:
    """Bundled scikit-image photo ``name``, float32 ``[TEXTURE_SIZE, TEXTURE_SIZE, 3]``, [0, 1]."""
    if name not in TEXTURES:
        raise ValueError(f"unknown texture {name!r}; known: {', '.join(TEXTURES)}")
    img = np.asarray(getattr(skdata, name)(), np.float64)
    img = img / 255.0 if img.max() > 1.0 else img
    img = np.repeat(img[..., None], 3, -1) if img.ndim == 2 else img[..., :3]
    out = resize(img, (TEXTURE_SIZE, TEXTURE_SIZE), order=1, anti_aliasing=True)
    out = np.clip(out, 0.0, 1.0).astype(np.float32)
    out.setflags(write=False)  # shared through the cache
    return out


@cache
def texture_planes(name: str) -> np.ndarray:
    """:func:`texture` ``name`` channel-major, float64 ``[3, TEXTURE_SIZE²]`` (the same
    values): the layout :func:`sample` gathers from fastest."""
    out = _channel_major(texture(name))
    out.setflags(write=False)  # shared through the cache
    return out


def _channel_major(tex: np.ndarray) -> np.ndarray:
    """``tex [th, tw, c]`` as float64 ``[c, th * tw]``, contiguous (the same values)."""
    th, tw = tex.shape[:2]
    return np.ascontiguousarray(tex.reshape(th * tw, -1).T, np.float64)


def sample(tex: np.ndarray, uv: np.ndarray, planes: np.ndarray | None = None) -> np.ndarray:
    """Bilinear, wrap-around lookup of ``tex [th, tw, 3]`` at ``uv [n, 2]`` -> ``[n, 3]``.

    ``top = tex[r0, c0] * (1 - ax) + tex[r0, c1] * ax``, the bottom row's likewise,
    then ``top * (1 - ay) + bottom * ay``, in float64. The work is done channel-major:
    each corner's channels gathered by one index into ``planes``, ``tex`` as ``[3, th
    * tw]`` (:func:`texture_planes`; made here if not given), and weighted along those
    rows: the same products and sums, several times faster than ``[n, 3]`` texels
    weighted by ``[n, 1]`` columns."""
    th, tw = tex.shape[:2]
    if planes is None:
        planes = _channel_major(tex)
    x = uv[:, 0] * tw - 0.5
    y = uv[:, 1] * th - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    ax, ay = x - x0, y - y0
    c0, r0 = _wrap(x0.astype(np.int64), tw), _wrap(y0.astype(np.int64), th)
    c1, r1 = _wrap(c0 + 1, tw), _wrap(r0 + 1, th)
    r0, r1 = r0 * tw, r1 * tw  # the rows' first texels

    def corner(r, c):  # [3, n]
        return np.take(planes, r + c, axis=1)

    top = corner(r0, c0) * (1 - ax) + corner(r0, c1) * ax
    bottom = corner(r1, c0) * (1 - ax) + corner(r1, c1) * ax
    return (top * (1 - ay) + bottom * ay).T


def _wrap(i: np.ndarray, size: int) -> np.ndarray:
    """``i % size`` (in ``[0, size)``), by a bit mask when ``size`` is a power of two:
    the same integers, a tenth of the time."""
    return i & (size - 1) if size & (size - 1) == 0 else i % size


@dataclass(frozen=True)
class Surface:
    """Appearance shared by all primitives: texture name, rgb tint, uv repeat (u, v)."""

    texture: str
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    repeat: tuple[float, float] = (1.0, 1.0)

    def colour(self, uv: np.ndarray) -> np.ndarray:
        """Albedo ``[n, 3]`` at texture coordinates ``uv [n, 2]``."""
        tex, planes = texture(self.texture), texture_planes(self.texture)
        return sample(tex, uv * np.asarray(self.repeat), planes) * np.asarray(self.tint)


def _nearest_root(a, b, c, extra_ok=None):
    """Smallest root ``t > T_MIN`` of ``a t^2 + 2 b t + c`` (``inf`` if none).

    ``extra_ok(t) -> bool [n]`` can reject roots (e.g. outside a cylinder's height).
    """
    disc = b * b - a * c
    sq = np.sqrt(np.maximum(disc, 0.0))
    safe_a = np.where(np.abs(a) > 1e-300, a, 1.0)
    best = np.full(a.shape, np.inf)
    for t in ((-b + sq) / safe_a, (-b - sq) / safe_a):  # both roots; keep the smaller valid one
        ok = (disc >= 0) & (np.abs(a) > 1e-300) & (t > T_MIN)
        if extra_ok is not None:
            ok &= extra_ok(t)
        best = np.where(ok & (t < best), t, best)
    return best


@dataclass(frozen=True)
class Sphere:
    """Sphere; uv = (longitude / 2 pi + 1/2, colatitude / pi) about the world z axis."""

    centre: tuple[float, float, float]
    radius: float
    surface: Surface

    def hit(self, origin, dirs):
        oc = np.asarray(origin, float) - np.asarray(self.centre)  # [3]
        t = _nearest_root(
            np.sum(dirs * dirs, -1), dirs @ oc, np.full(len(dirs), oc @ oc - self.radius**2)
        )
        p = (oc + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs) / self.radius  # [n, 3] unit
        u = 0.5 + np.arctan2(p[:, 1], p[:, 0]) / (2 * np.pi)
        v = np.arccos(np.clip(p[:, 2], -1.0, 1.0)) / np.pi
        return t, np.stack([u, v], -1)

    def distance(self, points):
        return np.abs(np.linalg.norm(points - np.asarray(self.centre), axis=-1) - self.radius)

    def bounds(self):
        c = np.asarray(self.centre, float)
        return c - self.radius, c + self.radius


@dataclass(frozen=True)
class Quad:
    """Parallelogram ``corner + a * edge_u + b * edge_v``, a, b in [0, 1]; uv = (a, b).

    Give ``corner`` as the top-left of the photo as seen from the side it faces,
    ``edge_u`` pointing right and ``edge_v`` down; ``edge_u`` and ``edge_v`` must be
    perpendicular.
    """

    corner: tuple[float, float, float]
    edge_u: tuple[float, float, float]
    edge_v: tuple[float, float, float]
    surface: Surface

    @cached_property
    def _edges(self):  # edge_u, edge_v as arrays and their squared lengths, worked out once
        eu, ev = np.asarray(self.edge_u, float), np.asarray(self.edge_v, float)
        return eu, ev, eu @ eu, ev @ ev

    @cached_property
    def _normal(self):  # edge_u x edge_v, worked out once (np.cross takes 0.1 ms)
        return np.cross(self.edge_u, self.edge_v)

    def _local(self, q):  # q [n, 3] relative to the corner -> (a, b) each [n]
        eu, ev, eu_sq, ev_sq = self._edges
        return q @ eu / eu_sq, q @ ev / ev_sq

    def hit(self, origin, dirs):
        p0, n = np.asarray(self.corner, float), self._normal
        denom = dirs @ n  # [n]
        ok = np.abs(denom) > 1e-12
        t = np.where(ok, ((p0 - origin) @ n) / np.where(ok, denom, 1.0), np.inf)
        q = np.asarray(origin, float) - p0 + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs
        a, b = self._local(q)
        ok &= (t > T_MIN) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
        return np.where(ok, t, np.inf), np.stack([a, b], -1)

    def distance(self, points):
        a, b = self._local(points - np.asarray(self.corner, float))
        a, b = np.clip(a, 0, 1)[:, None], np.clip(b, 0, 1)[:, None]
        closest = (
            np.asarray(self.corner) + a * np.asarray(self.edge_u) + b * np.asarray(self.edge_v)
        )
        return np.linalg.norm(points - closest, axis=-1)

    def bounds(self):
        p0, eu, ev = (np.asarray(x, float) for x in (self.corner, self.edge_u, self.edge_v))
        pts = np.stack([p0, p0 + eu, p0 + ev, p0 + eu + ev])
        return pts.min(0), pts.max(0)


@dataclass(frozen=True)
class Cylinder:
    """Side of a vertical (world z) cylinder, z in [z_lo, z_hi]; uv = (angle / 2 pi, from top)."""

    centre_xy: tuple[float, float]
    radius: float
    z_lo: float
    z_hi: float
    surface: Surface

    def hit(self, origin, dirs):
        o = np.asarray(origin, float)
        ox, oy = o[0] - self.centre_xy[0], o[1] - self.centre_xy[1]
        dx, dy, dz = dirs[:, 0], dirs[:, 1], dirs[:, 2]

        def in_height(t):
            z = o[2] + t * dz
            return (z >= self.z_lo) & (z <= self.z_hi)

        t = _nearest_root(
            dx * dx + dy * dy,
            ox * dx + oy * dy,
            np.full(len(dirs), ox * ox + oy * oy - self.radius**2),
            in_height,
        )
        tt = np.where(np.isfinite(t), t, 0.0)
        u = 0.5 + np.arctan2(oy + tt * dy, ox + tt * dx) / (2 * np.pi)
        v = (self.z_hi - (o[2] + tt * dz)) / (self.z_hi - self.z_lo)
        return t, np.stack([u, v], -1)

    def distance(self, points):
        radial = np.hypot(points[:, 0] - self.centre_xy[0], points[:, 1] - self.centre_xy[1])
        axial = np.maximum(np.maximum(self.z_lo - points[:, 2], points[:, 2] - self.z_hi), 0.0)
        return np.hypot(radial - self.radius, axial)

    def bounds(self):
        c = np.asarray(self.centre_xy, float)
        return np.r_[c - self.radius, self.z_lo], np.r_[c + self.radius, self.z_hi]


@dataclass(frozen=True)
class Disc:
    """Horizontal disc (a cylinder cap); uv maps its square [-r, r]^2 to [0, 1]^2."""

    centre: tuple[float, float, float]
    radius: float
    surface: Surface

    def hit(self, origin, dirs):
        o, c = np.asarray(origin, float), np.asarray(self.centre, float)
        ok = np.abs(dirs[:, 2]) > 1e-12
        t = np.where(ok, (c[2] - o[2]) / np.where(ok, dirs[:, 2], 1.0), np.inf)
        tt = np.where(np.isfinite(t), t, 0.0)
        x, y = o[0] + tt * dirs[:, 0] - c[0], o[1] + tt * dirs[:, 1] - c[1]
        ok &= (t > T_MIN) & (x * x + y * y <= self.radius**2)
        uv = np.stack([x, -y], -1) / (2 * self.radius) + 0.5
        return np.where(ok, t, np.inf), uv

    def distance(self, points):
        rho = np.hypot(points[:, 0] - self.centre[0], points[:, 1] - self.centre[1])
        return np.hypot(points[:, 2] - self.centre[2], np.maximum(rho - self.radius, 0.0))

    def bounds(self):
        c = np.asarray(self.centre, float)
        return c - [self.radius, self.radius, 0.0], c + [self.radius, self.radius, 0.0]


def box(
    centre,
    half,
    yaw: float,
    sides,
    top: Surface,
    bottom: Surface | None = None,
    inside: bool = False,
) -> list[Quad]:
    """Six :class:`Quad` faces of a box rotated by ``yaw`` (radians) about world z.

    ``half`` = half extents (hx, hy, hz) along the box's own axes; ``sides`` is one
    :class:`Surface` or four (faces +x, +y, -x, -y of the box). Side photos
    stand upright and unmirrored when seen from outside, or from inside with
    ``inside=True`` (a room: ``top`` is then the ceiling, ``bottom`` the floor).
    """
    c, (hx, hy, hz) = np.asarray(centre, float), half
    rot = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0, 0, 1]])
    ex, ey, ez = rot[:, 0], rot[:, 1], np.array([0.0, 0.0, 1.0])
    flip = -1.0 if inside else 1.0
    sides = [sides] * 4 if isinstance(sides, Surface) else list(sides)
    faces = []
    # (outward axis, image-right direction seen from outside, half extents along them)
    for side, (out, right, h_out, h_right) in zip(
        sides,
        ((ex, ey, hx, hy), (ey, -ex, hy, hx), (-ex, -ey, hx, hy), (-ey, ex, hy, hx)),
        strict=True,
    ):
        right = flip * right
        corner = c + h_out * out - h_right * right + hz * ez
        faces.append(Quad(tuple(corner), tuple(2 * h_right * right), tuple(-2 * hz * ez), side))
    bottom = bottom or top
    # a horizontal face seen from above: top-left at (-x, +y), u along +x, v along -y
    z_seen_from_above = (-hz, bottom) if inside else (hz, top)
    z_other = (hz, top) if inside else (-hz, bottom)
    for (dz, surf), sign in ((z_seen_from_above, 1.0), (z_other, -1.0)):
        corner = c + dz * ez - hx * ex + sign * hy * ey
        faces.append(Quad(tuple(corner), tuple(2 * hx * ex), tuple(-sign * 2 * hy * ey), surf))
    return faces


def cast(prims, origin: np.ndarray, dirs: np.ndarray):
    """Nearest hit of all primitives: ``t [n]`` (inf if none), albedo ``[n, 3]`` (0 if none).

    Each primitive is intersected only with the rays that pass through the sphere
    around its bounding box (:func:`_rays_near`): the same hits, far fewer rays tested
    for small primitives. That test is itself run only on the tiles of ``TILE``
    consecutive rays whose cone can reach the sphere (:func:`_tiles_near`, which never
    drops a ray the test passes), so the rays each primitive is intersected with are
    the same. Every ray's result depends on that ray alone, so the rays are cast
    :data:`~vbgs.render.camera.BLOCK` at a time, whose temporaries stay in the cache.
    """
    best_t = np.full(len(dirs), np.inf)
    rgb = np.zeros((len(dirs), 3))
    spheres = [_bounding_sphere(prim.bounds()) for prim in prims]
    for block in pixel_blocks(len(dirs)):
        _cast_block(prims, spheres, origin, dirs[block], best_t[block], rgb[block])
    return best_t, rgb


def _cast_block(prims, spheres, origin, dirs, best_t, rgb) -> None:
    """:func:`cast` of the rays ``dirs``, written into the views ``best_t`` and ``rgb``."""
    dir_sq = np.einsum("ij,ij->i", dirs, dirs)  # [n] |d|², rays need not be unit length
    cones = _tile_cones(dirs)
    for prim, sphere in zip(prims, spheres, strict=True):
        tiles = _tiles_near(sphere, origin, *cones)
        if not tiles.any():
            continue
        if tiles.all():
            near = _rays_near(sphere, origin, dirs, dir_sq)
            rows = slice(None) if near.all() else np.flatnonzero(near)  # all: views
        else:
            tried = _tile_rows(tiles, len(dirs))
            rows = tried[_rays_near(sphere, origin, dirs[tried], dir_sq[tried])]
        if not isinstance(rows, slice) and len(rows) == 0:
            continue
        t, uv = prim.hit(origin, dirs[rows])
        closer = t < best_t[rows]
        if np.any(closer):
            at = np.flatnonzero(closer) if isinstance(rows, slice) else rows[closer]
            best_t[at] = t[closer]
            rgb[at] = prim.surface.colour(uv[closer])


def _bounding_sphere(bounds) -> tuple[np.ndarray, float]:
    """Centre and radius of the sphere around the box ``bounds = (lo, hi)``, the radius
    widened a little (relative 1e-6, absolute 1e-9) so that rounding loses no ray."""
    lo, hi = (np.asarray(b, float) for b in bounds)
    return 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo) * (1 + 1e-6) + 1e-9


def _rays_near(sphere, origin, dirs, dir_sq) -> np.ndarray:
    """``[n]`` bool: the ray ``origin + t dirs`` (t > 0) comes within the radius of
    ``sphere = (centre, radius)`` (:func:`_bounding_sphere`) of its centre (a
    conservative test: every ray that can hit the box passes it). Each ray's answer
    depends on that ray alone."""
    centre, radius = sphere
    to_centre = centre - np.asarray(origin, float)
    along = dirs @ to_centre  # [n] (c - o) . d
    dist_sq = to_centre @ to_centre
    inside = dist_sq <= radius * radius
    # squared distance from the centre to the ray's closest point (ahead of the origin)
    closest_sq = dist_sq - np.where(along > 0, along * along / dir_sq, 0.0)
    return inside | ((along > 0) & (closest_sq <= radius * radius))


TILE = 256  # consecutive rays that cast culls together (a few pixels of a camera's row)
CONE_MARGIN = 1e-4  # radians added to a tile's cone: far more than the tests' rounding


def _tile_cones(dirs) -> tuple[np.ndarray, np.ndarray]:
    """Per tile of ``TILE`` consecutive rays (the last one shorter): its unit mean
    direction ``axis [k, 3]`` and ``half [k]``, the largest angle from it to one of
    its rays (NaN where a ray or the mean has no direction: never culled)."""
    n = len(dirs)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        pad = np.repeat(unit[-1:], -n % TILE, 0)  # copies of the last ray: the same cone
        unit = np.concatenate([unit, pad]).reshape(-1, TILE, 3)
        axis = unit.sum(1)
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        cos = np.einsum("ktj,kj->kt", unit, axis).min(1)
    return axis, np.arccos(np.clip(cos, -1.0, 1.0))


def _tiles_near(sphere, origin, axis, half) -> np.ndarray:
    """``[k]`` bool: the tile's cone (:func:`_tile_cones`) may hold a ray that
    :func:`_rays_near` passes. A ray whose angle to the centre exceeds the sphere's
    angular radius ``alpha`` misses it, and every ray of a tile lies within ``half`` of
    its axis, so a tile whose axis is more than ``half + alpha`` (plus
    ``CONE_MARGIN``) from the centre has none; an origin in or near the sphere keeps all."""
    centre, radius = sphere
    to_centre = centre - np.asarray(origin, float)
    dist = float(np.linalg.norm(to_centre))
    if dist <= radius * 1.01:
        return np.ones(len(axis), bool)
    alpha = np.arcsin(radius / dist)
    beta = np.arccos(np.clip(axis @ (to_centre / dist), -1.0, 1.0))
    return ~(beta > half + alpha + CONE_MARGIN)  # NaN (no direction) keeps the tile


def _tile_rows(tiles, n: int) -> np.ndarray:
    """Indices (ascending) of the rays in the tiles ``tiles [k]`` marks, below ``n``."""
    rows = (np.flatnonzero(tiles)[:, None] * TILE + np.arange(TILE)).ravel()
    return rows[rows < n]


def camera_rays(camera: Camera, samples: int = 1) -> np.ndarray:
    """World directions ``[h * w * samples², 3]`` with camera-frame z = 1: through the
    pixel centres (``samples = 1``), or through the centres of a ``samples x samples``
    grid of equal sub-pixels in each pixel, pixel-major (row, col, sub-row, sub-col).

    The rotation to the world is a matrix product of :data:`~vbgs.render.camera.BLOCK`
    rays at a time: each ray's row of the product is the same as in one product of all
    of them (its three sums do not depend on the other rows), but BLAS runs a block on
    one thread, where for a whole frame it starts its threads, which on a busy 2-core
    machine took 50 ms for 128 x 128 x 9 rays and a second at 640 x 480 x 9 (0.1 ms a block).
    """
    u, v = pixel_grid(camera)  # [h, w] pixel centres
    offsets = (np.arange(samples) + 0.5) / samples - 0.5  # sub-pixel centres, [-0.5, 0.5]
    u = u[:, :, None, None] + offsets[None, None, None, :]
    v = v[:, :, None, None] + offsets[None, None, :, None]
    u, v = np.broadcast_arrays(u, v)
    d_cam = np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones_like(u)], -1
    ).reshape(-1, 3)
    rot, out = np.asarray(camera.pose, float)[:3, :3].T, np.empty_like(d_cam)
    for rows in pixel_blocks(len(d_cam)):  # the same rows' products, one block at a time
        np.matmul(d_cam[rows], rot, out=out[rows])
    return out


def render(prims, camera: Camera, background=(1.0, 1.0, 1.0), samples: int = 1
           ) -> tuple[np.ndarray, np.ndarray]:
    """``rgb [h, w, 3]`` and z-depth ``[h, w]`` (0 where no surface is hit), float32.

    A pixel's colour is the mean over ``samples x samples`` rays through the centres of
    equal sub-pixels (a box filter over the pixel's area, as a camera integrates light
    and as NeRF-synthetic's renders are anti-aliased); ``samples = 1`` casts one ray
    through the pixel centre. Depth is the pixel centre's: the middle ray of an odd
    ``samples`` passes through it, otherwise one more ray is cast there. Both are exact
    up to float32 rounding.
    """
    if not (isinstance(samples, (int, np.integer)) and samples >= 1):
        raise ValueError(f"samples must be a positive integer (rays per pixel side), "
                         f"got {samples!r}")
    shape = (camera.height, camera.width)
    t, rgb = cast(prims, camera.position, camera_rays(camera, samples))
    rgb[~np.isfinite(t)] = background
    rgb = rgb.reshape(shape + (samples * samples, 3)).mean(2)
    if samples % 2:
        middle = (samples // 2) * (samples + 1)  # index of the central sub-pixel
        t = t.reshape(shape + (samples * samples,))[..., middle]
    else:
        t, _ = cast(prims, camera.position, camera_rays(camera))
    hit = np.isfinite(t)
    depth = np.where(hit, t, 0.0).reshape(shape)
    return np.clip(rgb, 0, 1).astype(np.float32), depth.astype(np.float32)


def distance_to_surfaces(prims, points: np.ndarray) -> np.ndarray:
    """Distance ``[n]`` from each point ``[n, 3]`` to the nearest primitive surface."""
    points = np.asarray(points, np.float64)
    return np.min([p.distance(points) for p in prims], axis=0)


def bounds_of(prims) -> tuple[np.ndarray, np.ndarray]:
    """Union of the primitives' boxes as float32 ``(lo [3], hi [3])``."""
    los, his = zip(*(p.bounds() for p in prims), strict=True)
    return np.min(los, 0).astype(np.float32), np.max(his, 0).astype(np.float32)
