"""Candidates by projection: a frame's points take their candidate components from the
map seen at the frame's pose, on the device, with no search structure kept between frames.

The sparse E-step scores each point against ``C`` candidates
(:mod:`vbgs.inference.candidates`). A host KD-tree finds the ``C`` nearest means in
space; for the points of a depth frame the camera already says which components can be
near a pixel, as KinectFusion's and SplaTAM's projective association do:

1. **project** every active component's mean ``m_k`` into the frame: camera-frame
   ``p_k = R^T (m_k + o - t)`` for the pose ``[R t]`` and the model's origin ``o``,
   pixel ``(f_x p_x / p_z + c_x, f_y p_y / p_z + c_y)``; components behind the camera
   or inactive are left out;
2. **bin** them into square tiles of ``T`` pixels (one spare tile round the image), each
   tile's list ordered nearest along the ray first and cut at ``L`` entries (a tile that
   sees more components keeps those in front): two sorts of ``k`` keys;
3. **choose**: each point, projected the same way, gathers the lists of its tile and the
   eight round it (``9 L`` components) and keeps the ``C`` nearest in space (``top_k`` of
   squared centred distances: elementwise, exact under TF32), the same rule as the
   KD-tree's over the components its neighbourhood holds.

A point whose neighbourhood holds fewer than ``C`` components keeps the ones it has; the
other entries are ``-1`` and take no responsibility (:func:`vbgs.inference.model.e_step_with`
masks them). Where a component near a point projects farther than a tile and a half
from it (a tile spans less space than the candidates reach), the projective list misses
it and the KD-tree would not; :func:`tile_size` sizes tiles from the component
spacing and the depth so this is rare, and the test holds the two paths to the same
responsibilities wherever they find the same components.

Cost: two sorts of the ``k`` projected means, ``9 L`` distances and a ``top_k`` per point;
no host round trip. The candidate rule reads the assigning model and the frame only (the
camera and the points), so under prior assignment a stream still sums per-frame
statistics: the same frames in any order or grouping give the same posterior when each
frame keeps its own camera (a batch of frames is searched frame by frame).
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# Components kept per tile (nearest along the ray first).
LIST_LENGTH = 16
# A tile spans about this many component spacings at the frame's median depth: with
# the eight tiles round a point's own, its candidates may lie up to 1.5 tiles (3
# spacings) away across the image, beyond the mapper's reach of 2 cells.
TILE_SPACINGS = 1.0
# Each tile keeps this many times C components nearest its points, each point the C
# nearest of those to itself (a tile's points differ in depth and place).
SHORTLIST = 2
# Tiles are at least this many pixels a side (smaller ones cost more lists than they save).
MIN_TILE = 2


class Tiling(NamedTuple):
    """Static layout of the projective search (hashable: one compilation per layout)."""

    width: int  # the frame's pixels
    height: int
    tile: int  # T, pixels a tile side
    list_length: int  # L, components kept per tile
    n_candidates: int  # C
    shortlist: int = 0  # M > C: each tile keeps M, each point the C nearest of them

    @property
    def tiles_x(self) -> int:  # with one spare tile each side
        return -(-self.width // self.tile) + 2

    @property
    def tiles_y(self) -> int:
        return -(-self.height // self.tile) + 2


class View(NamedTuple):
    """A frame's camera as the search reads it (device arrays, so a new pose does not
    recompile): ``rot [3, 3]`` world-to-camera rotation ``R^T``, ``shift [3]`` the model's
    origin in the camera frame ``R^T (o - t)`` (found in float64 on the host, so points far
    from the origin keep their precision), ``intrinsics [4]`` ``f_x, f_y, c_x, c_y``."""

    rot: jnp.ndarray
    shift: jnp.ndarray
    intrinsics: jnp.ndarray


def view(camera, origin, dtype=jnp.float32) -> View:
    """The :class:`View` of ``camera`` (:class:`vbgs.render.camera.Camera`, camera-to-world
    pose) for a model centred at ``origin [3]``."""
    rot_t, shift = world_to_camera(camera, origin)
    intr = np.array([camera.fx, camera.fy, camera.cx, camera.cy], np.float64)
    return View(jnp.asarray(rot_t, dtype), jnp.asarray(shift, dtype), jnp.asarray(intr, dtype))


def world_to_camera(camera, origin) -> tuple[np.ndarray, np.ndarray]:
    """``R^T [3, 3]`` and ``R^T (o - t) [3]`` (float64, host): centred positions to the
    camera frame of ``camera`` for a model centred at ``origin``."""
    pose = np.asarray(camera.pose, np.float64)
    rot_t = pose[:3, :3].T
    return rot_t, rot_t @ (np.asarray(origin, np.float64).reshape(3) - pose[:3, 3])


def tile_size(camera, spacing: float, depth: float) -> int:
    """Pixels a tile side: :data:`TILE_SPACINGS` component spacings (``spacing``, world
    units, e.g. the growth rule's cell) seen at ``depth`` (the frame's median), at least
    :data:`MIN_TILE` and at most a quarter of the frame's shorter side."""
    focal = 0.5 * (float(camera.fx) + float(camera.fy))
    t = TILE_SPACINGS * focal * float(spacing) / max(float(depth), 1e-30)
    cap = max(MIN_TILE, min(int(camera.width), int(camera.height)) // 4)
    return int(min(max(MIN_TILE, math.ceil(t)), cap))


def plan(camera, spacing: float, depth: float, n_candidates: int,
         list_length: int = LIST_LENGTH) -> Tiling:
    """The :class:`Tiling` of a frame like ``camera``'s (see :func:`tile_size`)."""
    return Tiling(int(camera.width), int(camera.height), tile_size(camera, spacing, depth),
                  int(list_length), int(n_candidates), SHORTLIST * int(n_candidates))


def _tiles(v: View, x: jnp.ndarray, tiling: Tiling) -> tuple[jnp.ndarray, jnp.ndarray,
                                                             jnp.ndarray, jnp.ndarray]:
    """Tile coordinates ``(tx, ty) [n]`` (with the spare border: 0 and the last are outside
    the image), camera depth ``z [n]`` and whether the point is in front of the camera
    and within the tiled area, of centred positions ``x [n, 3]``."""
    p = x @ v.rot.T + v.shift  # [n, 3] camera frame (three products of 3 terms: exact enough)
    z = p[:, 2]
    front = z > 0
    safe = jnp.where(front, z, 1.0)
    u = v.intrinsics[0] * p[:, 0] / safe + v.intrinsics[2]
    w = v.intrinsics[1] * p[:, 1] / safe + v.intrinsics[3]
    tx = jnp.floor(u / tiling.tile).astype(jnp.int32) + 1
    ty = jnp.floor(w / tiling.tile).astype(jnp.int32) + 1
    inside = front & (tx >= 0) & (tx < tiling.tiles_x) & (ty >= 0) & (ty < tiling.tiles_y)
    return tx, ty, z, inside


def tile_lists(means: jnp.ndarray, active: jnp.ndarray, v: View, tiling: Tiling
               ) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Each tile's components, nearest along the ray first: ids ``[tiles, L]`` (int32) and
    ``count [tiles]`` (how many of the ``L`` entries are real). ``means [k, 3]`` centred,
    ``active [k]`` bool."""
    k = means.shape[0]
    n_tiles = tiling.tiles_x * tiling.tiles_y
    tx, ty, z, inside = _tiles(v, means, tiling)
    keep = inside & active
    tile = jnp.where(keep, ty * tiling.tiles_x + tx, n_tiles)  # n_tiles: not listed
    # one sort by (tile, depth): each tile's components contiguous, nearest first
    sorted_tile, _, order = jax.lax.sort((tile, jnp.where(keep, z, jnp.inf),
                                          jnp.arange(k, dtype=jnp.int32)), num_keys=2)
    count = jnp.zeros(n_tiles + 1, jnp.int32).at[tile].add(1)[:n_tiles]
    start = jnp.cumsum(count) - count
    at = jnp.minimum(start[:, None] + jnp.arange(tiling.list_length), k - 1)
    return order[at], jnp.minimum(count, tiling.list_length)


def neighbourhoods(lists: jnp.ndarray, count: jnp.ndarray, tiling: Tiling) -> jnp.ndarray:
    """Each tile's pool, the lists of the tile and the eight round it: ids
    ``[tiles, 9 L]``, -1 where a list is shorter than ``L``."""
    tx, ty = tiling.tiles_x, tiling.tiles_y
    real = jnp.arange(tiling.list_length) < count[:, None]
    ids = jnp.where(real, lists, -1).reshape(ty, tx, -1)
    ids = jnp.pad(ids, ((1, 1), (1, 1), (0, 0)), constant_values=-1)  # an empty ring
    return jnp.concatenate([ids[1 + dy:1 + dy + ty, 1 + dx:1 + dx + tx]
                            for dy in (-1, 0, 1) for dx in (-1, 0, 1)], -1).reshape(ty * tx, -1)


def point_tiles(x: jnp.ndarray, w: jnp.ndarray, v: View, tiling: Tiling
                ) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """Each point's tile ``[n]`` (points outside the tiled area, or of weight 0, in the
    spare border, whose lists are empty), and each tile's nearest and farthest
    measured depth ``[tiles]`` (+inf / -inf where it holds no point)."""
    tx, ty, z, inside = _tiles(v, x, tiling)
    n_tiles = tiling.tiles_x * tiling.tiles_y
    held = inside & (w > 0)
    tile = jnp.where(held, ty * tiling.tiles_x + tx, 0)
    near = jnp.full(n_tiles, jnp.inf, x.dtype).at[tile].min(jnp.where(held, z, jnp.inf))
    far = jnp.full(n_tiles, -jnp.inf, x.dtype).at[tile].max(jnp.where(held, z, -jnp.inf))
    return tile, near, far


def tile_candidates(pool: jnp.ndarray, means: jnp.ndarray, v: View, near: jnp.ndarray,
                    far: jnp.ndarray, tiling: Tiling) -> jnp.ndarray:
    """Each tile's ``C`` candidates ``[tiles, C]`` (-1 where its pool held fewer): the
    pooled components nearest to the tile's measured points, the distance of a component
    to the tile being its distance across the image to the tile's centre (pixels times
    its depth over the focal length) and along the ray to the depth range the tile's
    points span."""
    tx = jnp.arange(tiling.tiles_x)
    ty = jnp.arange(tiling.tiles_y)
    cu = ((tx - 1 + 0.5) * tiling.tile)[None, :].repeat(tiling.tiles_y, 0).reshape(-1)
    cv = ((ty - 1 + 0.5) * tiling.tile)[:, None].repeat(tiling.tiles_x, 1).reshape(-1)
    p = means @ v.rot.T + v.shift  # [k, 3]
    z = jnp.maximum(p[:, 2], 1e-30)
    fx, fy, px, py = v.intrinsics
    half = 0.5 * tiling.tile
    ids = jnp.maximum(pool, 0)
    pz = z[ids]  # [tiles, 9 L]
    pu = fx * p[ids, 0] / pz + px
    pv = fy * p[ids, 1] / pz + py
    # across the image: how far the projected mean lies outside the tile, in world units
    # at the component's depth; along the ray: how far it lies outside the points' range
    gap_u = jnp.maximum(jnp.abs(pu - cu[:, None]) - half, 0.0) * pz / fx
    gap_v = jnp.maximum(jnp.abs(pv - cv[:, None]) - half, 0.0) * pz / fy
    gap_z = jnp.maximum(jnp.maximum(near[:, None] - pz, pz - far[:, None]), 0.0)
    score = gap_u**2 + gap_v**2 + gap_z**2
    score = jnp.where((pool >= 0) & jnp.isfinite(near)[:, None], score, jnp.inf)
    c = min(max(tiling.n_candidates, tiling.shortlist), pool.shape[1])
    neg, at = jax.lax.top_k(-score, c)
    return jnp.where(jnp.isfinite(neg), jnp.take_along_axis(pool, at, 1), -1)


def nearest(means: jnp.ndarray, x: jnp.ndarray, cand: jnp.ndarray, c: int
            ) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The ``c`` candidates of ``cand [n, M]`` nearest each point ``[n, c]`` (all of them,
    unordered, when ``c >= M``) and its squared distance to the nearest ``[n]`` (inf:
    none)."""
    near = means[jnp.maximum(cand, 0)]  # [n, M, 3]
    d2 = sum((x[:, i, None] - near[..., i]) ** 2 for i in range(x.shape[1]))
    d2 = jnp.where(cand >= 0, d2, jnp.inf)
    if c >= cand.shape[1]:
        return cand, jnp.min(d2, -1)
    neg, at = jax.lax.top_k(-d2, c)
    return jnp.where(jnp.isfinite(neg), jnp.take_along_axis(cand, at, 1), -1), -neg[:, 0]


@partial(jax.jit, static_argnames=("tiling",))
def search(means: jnp.ndarray, active: jnp.ndarray, v: View, x: jnp.ndarray, w: jnp.ndarray,
           tiling: Tiling) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Each point's candidates ``[n, C]`` (its tile's, :func:`tile_candidates`; -1 where
    fewer) and squared distance to its nearest candidate ``[n]``; the points ``x [n, 3]``
    (weights ``w [n]``, 0: padding) and the means ``[k, 3]`` both centred on the model's
    origin."""
    lists, count = tile_lists(means, active, v, tiling)
    pool = neighbourhoods(lists, count, tiling)
    tile, near, far = point_tiles(x, w, v, tiling)
    cand = tile_candidates(pool, means, v, near, far, tiling)[tile]
    return nearest(means, x, cand, tiling.n_candidates)
