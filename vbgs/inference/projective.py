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
   sees more components keeps those in front): ``L`` rounds of a minimum per tile;
3. **choose per tile**: each tile pools its own list and the eight round it (``9 L``
   components) and keeps the ``C`` nearest its measured points (:func:`tile_candidates`:
   across the image, the distance to the tile's box at the component's depth; along the
   ray, the distance to the depth range its points span, ties broken towards its
   nearest, mean and farthest depth), and every point of the tile takes those ``C``.
   With ``Tiling.shortlist = M > C`` a tile keeps ``M`` and each point the ``C`` nearest
   of them to itself, the KD-tree's rule over a shorter list (on a CPU that choice costs
   ten times the rest, :data:`SHORTLIST`).

A point whose tile holds fewer than ``C`` components keeps the ones it has; the other
entries are ``-1`` and take no responsibility (:func:`vbgs.inference.model.e_step_with`
masks them). A component near a point but projecting more than a tile and a half from
its tile is missed where the KD-tree would list it; :func:`tile_size` sizes tiles from
the component spacing and the depth so this is rare (on the object at 128 px the
nearest component of 98% of the points is listed), and the tests hold the two paths to
the same responsibilities wherever they list the same components. A point listed no
component within its reach (far ground, where a tile spans many spacings: 3% of the
walk's points at 640 x 480) is, under prior assignment, searched again in a KD-tree over
the reference's means and learned from its nearest
(:meth:`vbgs.inference.stepper.Stepper._missed`): the tree is built only for a frame
that misses points, once per reference.

Cost: ``L`` scatters of the ``k`` projected means, ``9 L`` scores and a ``top_k`` per tile, a
gather per point; no host round trip. Precision: float32 throughout; the projection is
three products of three terms, the scores differences of nearby lengths. The candidate rule reads the assigning model and the frame only (the
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
# the eight tiles round a point's own, its candidates may lie up to 1.5 tiles away
# across the image. Smaller tiles share candidates among fewer points, nearer each
# other. Chosen on validation views (`python -m experiments.studies.val_probe fit-scene
# --scene S --search projective`, fit-scene's defaults, the constant set in this module),
# object / room / walk: 1.0 gave 26.46 / 22.35 / 20.37 dB, 0.7 26.46 / 22.71 / 21.22,
# 0.5 26.46 / 22.71 / 21.05, 0.35 26.46 / 22.71 / 20.46 (at 128 px the object's tiles
# are MIN_TILE pixels at every value, the room's from 0.7 down); the KD-tree 26.59 /
# 22.72 / 21.62. The
# walk's far ground is what is left: 4.7% of its points find no candidate within reach.
TILE_SPACINGS = 0.7
# Each tile keeps this many times C components nearest its points, each point the C
# nearest of those to itself (a tile's points differ in depth and place). 1: every point
# takes its tile's C. On a CPU the per-point choice costs ten times the rest of the
# search at 640 x 480 (1.2 s against 0.12 s of CPU, 307k points) for the same share of
# points whose nearest component is listed.
SHORTLIST = 1
# Within the depth range a tile's points span, components nearer one of its nearest,
# mean and farthest depth rank first, by this weight on the squared distance to it.
TIE_WEIGHT = 0.25
# Tiles are at least this many pixels a side (smaller ones cost more lists than they save).
MIN_TILE = 2
# A frame is cut into at most this many tiles across its shorter side. Each tile pays for
# its lists (nine pooled, a top-C, a gather of C terms) whatever it holds, so at a
# sensor's size small tiles cost more in lists than in scores: the room at 640 x 480
# under the Kinect (100k components, 4-pixel tiles from TILE_SPACINGS) spent 0.12 of its
# 0.32 s step on lists. Chosen on validation views at that size (the room, 20 frames, 2
# validation views; one-off val_probe runs with the tile side forced, docs/performance.md):
# tiles of 4, 6, 8, 12 and 16 pixels gave 22.54, 22.57, 22.63, 22.90 and 22.46 dB, within
# what one stream's 2 views tell apart; the step took 0.32-0.39 s at 4 and 0.18-0.20 s at
# 8 (a recorded frame). 64 across gives 8 at 480 rows and leaves 128-pixel frames at
# MIN_TILE.
TILES_ACROSS = 64


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
    :data:`MIN_TILE` and a :data:`TILES_ACROSS`-th of the frame's shorter side, at most a
    quarter of it."""
    focal = 0.5 * (float(camera.fx) + float(camera.fy))
    t = TILE_SPACINGS * focal * float(spacing) / max(float(depth), 1e-30)
    side = min(int(camera.width), int(camera.height))
    cap = max(MIN_TILE, side // 4)
    return int(min(max(MIN_TILE, math.ceil(t), -(-side // TILES_ACROSS)), cap))


def plan(camera, spacing: float, depth: float, n_candidates: int,
         list_length: int = LIST_LENGTH) -> Tiling:
    """The :class:`Tiling` of a frame like ``camera``'s (see :func:`tile_size`)."""
    return Tiling(int(camera.width), int(camera.height), tile_size(camera, spacing, depth),
                  int(list_length), int(n_candidates), SHORTLIST * int(n_candidates))


class Projected(NamedTuple):
    """Centred positions seen from a :class:`View`: pixel ``u, v [n]``, camera depth
    ``z [n]`` (1 behind the camera, where ``front`` is False)."""

    u: jnp.ndarray
    v: jnp.ndarray
    z: jnp.ndarray
    front: jnp.ndarray


def project(v: View, x: jnp.ndarray) -> Projected:
    """:class:`Projected` of centred positions ``x [n, 3]``."""
    p = x @ v.rot.T + v.shift  # [n, 3] camera frame (three products of 3 terms: exact enough)
    front = p[:, 2] > 0
    z = jnp.where(front, p[:, 2], 1.0)
    return Projected(v.intrinsics[0] * p[:, 0] / z + v.intrinsics[2],
                     v.intrinsics[1] * p[:, 1] / z + v.intrinsics[3], z, front)


def _tiles(seen: Projected, tiling: Tiling) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """Tile coordinates ``(tx, ty) [n]`` (with the spare border: 0 and the last are outside
    the image) and whether each position is in front of the camera and within the tiled
    area."""
    tx = jnp.floor(seen.u / tiling.tile).astype(jnp.int32) + 1
    ty = jnp.floor(seen.v / tiling.tile).astype(jnp.int32) + 1
    inside = seen.front & (tx >= 0) & (tx < tiling.tiles_x) & (ty >= 0) \
        & (ty < tiling.tiles_y)
    return tx, ty, inside


def tile_lists(seen: Projected, active: jnp.ndarray, tiling: Tiling
               ) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Each tile's components, nearest along the ray first (ties: the lower slot first):
    ids ``[tiles, L]`` (int32, -1 past the real entries) and ``count [tiles]`` (how many
    of the ``L`` entries are real). ``seen``: the ``k`` component means projected
    (:func:`project`), ``active [k]`` bool.

    ``L`` rounds of a minimum per tile, each taking every tile's nearest component not
    yet listed: two scatters of ``k`` values a round. A sort of the ``k`` keys by tile
    and depth gives the same lists at two to three times the cost on a CPU (a recorded
    room frame at 640 x 480, 100k means, timed alone on 2 loaded cores: XLA's sort 37
    ms, the rounds 15; projection, lists and pools together 21 against 33 ms)."""
    k = seen.z.shape[0]
    n_tiles = tiling.tiles_x * tiling.tiles_y
    tx, ty, inside = _tiles(seen, tiling)
    keep = inside & active
    tile = jnp.where(keep, ty * tiling.tiles_x + tx, n_tiles)  # n_tiles: not listed
    slot = jnp.arange(k, dtype=jnp.int32)
    none = jnp.iinfo(jnp.int32).max

    def nearest_left(r, carry):
        z, lists = carry
        near = jnp.full(n_tiles + 1, jnp.inf, z.dtype).at[tile].min(z)
        first = jnp.full(n_tiles + 1, none, jnp.int32).at[tile].min(
            jnp.where((z == near[tile]) & (z < jnp.inf), slot, none))
        return jnp.where(slot == first[tile], jnp.inf, z), lists.at[:, r].set(first[:n_tiles])

    lists = jnp.full((n_tiles, tiling.list_length), none, jnp.int32)
    _, lists = jax.lax.fori_loop(0, tiling.list_length, nearest_left,
                                 (jnp.where(keep, seen.z, jnp.inf), lists))
    count = jnp.minimum(jnp.zeros(n_tiles + 1, jnp.int32).at[tile].add(1)[:n_tiles],
                        tiling.list_length)
    return jnp.where(lists == none, -1, lists), count


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
                ) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Each point's tile ``[n]`` (points outside the tiled area, or of weight 0, in the
    spare border, whose lists are empty), and each tile's nearest, mean and farthest
    measured depth ``[tiles, 3]`` (+inf where it holds no point)."""
    seen = project(v, x)
    z = seen.z
    tx, ty, inside = _tiles(seen, tiling)
    n_tiles = tiling.tiles_x * tiling.tiles_y
    held = inside & (w > 0)
    tile = jnp.where(held, ty * tiling.tiles_x + tx, 0)
    near = jnp.full(n_tiles, jnp.inf, x.dtype).at[tile].min(jnp.where(held, z, jnp.inf))
    far = jnp.full(n_tiles, -jnp.inf, x.dtype).at[tile].max(jnp.where(held, z, -jnp.inf))
    total = jnp.zeros(n_tiles, x.dtype).at[tile].add(jnp.where(held, z, 0.0))
    count = jnp.zeros(n_tiles, x.dtype).at[tile].add(held.astype(x.dtype))
    mean = jnp.where(count > 0, total / jnp.maximum(count, 1.0), jnp.inf)
    return tile, jnp.stack([near, mean, jnp.where(count > 0, far, jnp.inf)], -1)


def tile_candidates(pool: jnp.ndarray, seen: Projected, fx, fy, depths: jnp.ndarray,
                    tiling: Tiling) -> jnp.ndarray:
    """Each tile's ``C`` candidates ``[tiles, C]`` (-1 where its pool held fewer): the
    pooled components nearest to the tile's measured points, the distance of a component
    to the tile being its distance across the image to the tile's box (pixels times its
    depth over the focal length) and along the ray to the nearest of the tile's nearest,
    mean and farthest measured depth ``depths [tiles, 3]`` (a tile across a depth edge
    keeps components of both surfaces; one on a slanted surface, of its middle too).
    ``seen``: the component means projected, ``fx``, ``fy`` the focal lengths."""
    tx = jnp.arange(tiling.tiles_x)
    ty = jnp.arange(tiling.tiles_y)
    cu = ((tx - 1 + 0.5) * tiling.tile)[None, :].repeat(tiling.tiles_y, 0).reshape(-1)
    cv = ((ty - 1 + 0.5) * tiling.tile)[:, None].repeat(tiling.tiles_x, 1).reshape(-1)
    half = 0.5 * tiling.tile
    ids = jnp.maximum(pool, 0)  # every listed component is in front: its z is its depth
    pz, pu, pv = seen.z[ids], seen.u[ids], seen.v[ids]  # [tiles, 9 L]
    # across the image: how far the projected mean lies outside the tile, in world units
    # at the component's depth; along the ray: how far it lies outside the points' range
    gap_u = jnp.maximum(jnp.abs(pu - cu[:, None]) - half, 0.0) * pz / fx
    gap_v = jnp.maximum(jnp.abs(pv - cv[:, None]) - half, 0.0) * pz / fy
    slab = jnp.maximum(jnp.maximum(depths[:, None, 0] - pz, pz - depths[:, None, 2]), 0.0)
    nearest = jnp.min(jnp.abs(pz[..., None] - depths[:, None, :]), -1)
    score = gap_u**2 + gap_v**2 + slab**2 + TIE_WEIGHT * nearest**2
    score = jnp.where((pool >= 0) & jnp.isfinite(depths[:, :1]), score, jnp.inf)
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
def tile_pool(means: jnp.ndarray, active: jnp.ndarray, v: View, tiling: Tiling
              ) -> tuple[Projected, jnp.ndarray]:
    """The means ``[k, 3]`` (``active [k]``) as the frame at ``v`` sees them, projected
    once a frame (binning and ranking read the same pixels), and each tile's pool of
    components (:func:`tile_lists`, :func:`neighbourhoods`), which
    :func:`tile_candidates` ranks for the tile's depths."""
    seen = project(v, means)
    lists, count = tile_lists(seen, active, tiling)
    return seen, neighbourhoods(lists, count, tiling)


def search(means: jnp.ndarray, active: jnp.ndarray, v: View, x: jnp.ndarray, w: jnp.ndarray,
           tiling: Tiling) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Each point's candidates ``[n, C]`` (its tile's, :func:`tile_candidates`; -1 where
    fewer) and squared distance to its nearest candidate ``[n]``; the points ``x [n, 3]``
    (weights ``w [n]``, 0: padding) and the means ``[k, 3]`` both centred on the model's
    origin."""
    seen, pool = tile_pool(means, active, v, tiling)
    tile, depths = point_tiles(x, w, v, tiling)
    cand = tile_candidates(pool, seen, v.intrinsics[0], v.intrinsics[1], depths,
                           tiling)[tile]
    return nearest(means, x, cand, tiling.n_candidates)
