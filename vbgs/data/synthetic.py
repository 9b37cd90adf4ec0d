"""Synthetic RGB-D scenes with exact ground truth, for any camera.

Three scenes are ray cast analytically (:mod:`vbgs.data.raycast`) from textured
primitives, so colour and z-depth are exact up to float32 rounding:

* ``"object"``: object-centric, like NeRF-synthetic. A textured platform
  (top at z = 0) carrying a sphere, a box and a capped cylinder, all inside
  about [-1, 1]^3, seen from an orbit of radius ``ORBIT_RADIUS`` around
  ``ORBIT_TARGET``. Pixels that hit nothing have depth 0 (invalid) and rgb
  ``OBJECT_BACKGROUND`` (white, as in NeRF-synthetic).
* ``"room"``: a closed 6 x 5 x 2.6 room (floor at z = 0) with a photo on each
  wall, tiled floor and ceiling, a table with a ball on it, a ball on the floor
  and a stool, seen along a walkthrough inside it. Every pixel has valid depth.
* ``"walk"``: an open street. A gravel road along +x between grass verges (ground
  at z = 0, 70 x 52 units), five houses (walls with a photo on the side facing the
  street), five trees, four rocks and two lamp posts on both sides of the first
  40 units, and three tall buildings 45-60 units out, so depth reaches 60. The
  camera walks ``WALK_LENGTH`` = 32 units forward along the road at eye height
  ``WALK_EYE`` = 1.5 and never comes back: later frames see ground the first ones
  saw far away or not at all. Pixels that hit nothing (the sky, a fifth to
  two fifths of each frame) have depth 0 (invalid) and rgb ``WALK_SKY`` (light blue).
* ``"walk-long"``: the same street continued for ``WALK_LONG_LENGTH`` (about 108) units:
  200 frames step as far apart as the walk's 60 (``WALK_LENGTH / 59``), so a 200-frame
  stream keeps meeting new ground. Its first ``WALK_BLOCK`` units are the walk's
  street, object for object; the houses, trees, rocks and posts repeat every
  ``WALK_BLOCK`` units (each repeat jittered afresh, the house photos rotated), the
  path weaves and the gaze wanders at the walk's rate per unit, and the far buildings
  and the end of the ground stand as far beyond the longer path's end.
* ``"object-change"``, ``"room-change"``, ``"walk-change"``: each walked twice, its world
  changed between the laps (:mod:`vbgs.data.changing`, :func:`changing_scene`).

World axes: z up, units are metres-like scene units. Training views follow a
continuous path (frame i and i + 1 are neighbouring views, so streaming order
matters): closed for the object and the room (the last view is beside the first),
open for the walk; test views are drawn off that path under the same ``seed``
(along the whole of the walk's); validation views (:func:`object_val_poses`,
:func:`room_val_poses`, :func:`walk_val_poses`) are drawn the way test views are,
from a separate random stream (``[seed, scene tag, VAL_STREAM]``), so adding them
leaves the training and test views bit-identical.
``seed`` also jitters object placement, so different seeds give different scenes
and the same seed gives bit-identical frames.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from functools import partial

import numpy as np

from vbgs.data.changing import two_laps
from vbgs.data.raycast import Cylinder, Disc, Quad, Sphere, Surface, bounds_of, box, render
from vbgs.data.scene import Frame, Scene
from vbgs.render.camera import from_fov, look_at

OBJECT_BACKGROUND = (1.0, 1.0, 1.0)  # white, as NeRF-synthetic composites its RGBA images
OBJECT_FOV_X = 0.6911112070083618  # radians: NeRF-synthetic's camera_angle_x
ORBIT_RADIUS = 4.0  # camera distance from ORBIT_TARGET
ORBIT_TARGET = (0.0, 0.0, 0.3)
ORBIT_ELEVATION = (np.deg2rad(10.0), np.deg2rad(55.0))  # range of view elevations
ROOM_FOV_X = np.deg2rad(75.0)
ROOM_CENTRE, ROOM_HALF = (0.0, 0.0, 1.3), (3.0, 2.5, 1.3)  # floor at z = 0, ceiling at 2.6
ROOM_WALK_RADII = (2.2, 1.7)  # walkthrough ellipse in the room (x, y), well clear of the objects
ROOM_WALK_HEIGHT = 1.45  # eye height of the walkthrough
ROOM_LOOK_TARGET = np.array([0.0, 0.0, 0.8])  # the walkthrough looks about this point
WALK_FOV_X = np.deg2rad(75.0)
WALK_SKY = (0.62, 0.78, 0.95)  # light blue: the colour of every ray that hits nothing
WALK_LENGTH = 32.0  # the path runs from x = 0 to x = WALK_LENGTH and never comes back
WALK_FRAMES = 60  # the walk's default frames: WALK_LENGTH / (WALK_FRAMES - 1) units a step
WALK_LONG_FRAMES = 200  # "walk-long": this many frames at the walk's step
WALK_LONG_LENGTH = WALK_LENGTH * (WALK_LONG_FRAMES - 1) / (WALK_FRAMES - 1)  # 107.93
WALK_BLOCK = 40.0  # the street's houses, trees, rocks and posts repeat this often (x)
WALK_WEAVE, WALK_WEAVE_PERIODS = 0.6, 1.25  # the path swings this far left/right (y), so often
WALK_EYE = 1.5  # eye height of the walk
WALK_WANDER, WALK_WANDER_PERIODS = 0.35, 2.0  # gaze yaw about the path's heading (rad), so often
WALK_PITCH = np.deg2rad(4.0)  # the gaze dips this far below the horizon
VAL_STREAM = 3  # third entry of the validation views' rng seed (train/test use [seed, tag])
N_VAL = 4  # validation views per synthetic scene by default
# Rays per pixel side: a pixel's colour is the mean of SAMPLES x SAMPLES rays spread
# over its area (a box filter, as a camera integrates light and as NeRF-synthetic's
# renders are anti-aliased); its depth is the centre ray's. With one ray per pixel
# every silhouette is a hard, aliased step that no renderer with smooth footprints
# (Gaussian splats) can reproduce: on the object scene two thirds of VBGS's squared
# error sat in the pixels beside depth edges. ``samples=1`` gives the aliased frames.
SAMPLES = 3
FRAME_THREADS = 2  # frames rendered at once (this project's machines have 2 cores)


def object_primitives(seed: int = 0, changed: bool = False) -> list:
    """Primitives of the ``"object"`` scene; ``seed`` jitters placement and yaw.
    ``changed``: the scene after its change events (:mod:`vbgs.data.changing`): the sphere
    taken away, the crate moved onto its place, a new ball added, and the cylinder's
    texture replaced."""
    rng = np.random.default_rng(seed)
    jx, jy, jz = rng.uniform(-0.05, 0.05, (3, 2))  # [3, 2] xy jitters
    yaw = rng.uniform(0.0, np.pi / 2)
    sx, sy = 0.40 + jx[0], -0.35 + jx[1]
    cx, cy = 0.45 + jz[0], 0.50 + jz[1]
    platform = box(
        (0.0, 0.0, -0.05),
        (0.95, 0.95, 0.05),
        0.0,
        Surface("brick", (0.85, 0.6, 0.45), (4.0, 1.0)),
        Surface("gravel", (0.7, 0.75, 0.9), (3.0, 3.0)),
    )
    crate_xy = (sx, sy) if changed else (-0.40 + jy[0], 0.30 + jy[1])
    crate = box(
        (*crate_xy, 0.30),
        (0.30, 0.30, 0.30),
        yaw,
        Surface("coffee"),
        Surface("rocket"),
    )
    cap = Surface("immunohistochemistry")
    side = Surface("rocket" if changed else "chelsea", repeat=(2.0, 1.0))
    kept = [Sphere((sx, sy, 0.45), 0.45, Surface("astronaut"))] if not changed else \
        [Sphere((-0.50 + jy[0], -0.50 + jy[1], 0.22), 0.22, Surface("colorwheel"))]
    return [
        *platform,
        *crate,
        *kept,
        Cylinder((cx, cy), 0.22, 0.0, 0.7, side),
        Disc((cx, cy, 0.7), 0.22, cap),
        Disc((cx, cy, 0.0), 0.22, cap),
    ]


def room_primitives(seed: int = 0, changed: bool = False) -> list:
    """Primitives of the ``"room"`` scene; ``seed`` jitters the furniture. ``changed``:
    the room after its change events (:mod:`vbgs.data.changing`): the ball on the table
    taken away, the ball on the floor moved across the room, a crate added by the wall
    and the stool's texture replaced."""
    rng = np.random.default_rng(seed)
    j = rng.uniform(-0.08, 0.08, (4, 2))  # [4, 2] xy jitters
    yaw = rng.uniform(0.0, np.pi)
    walls = [Surface(n, repeat=(2.0, 1.0)) for n in ("astronaut", "coffee", "chelsea", "rocket")]
    room = box(
        ROOM_CENTRE,
        ROOM_HALF,
        0.0,
        walls,
        top=Surface("gravel", (0.95, 0.92, 0.85), (3.0, 3.0)),
        bottom=Surface("brick", (0.8, 0.55, 0.4), (6.0, 5.0)),
        inside=True,
    )
    tx, ty = 0.40 + j[0, 0], 0.10 + j[0, 1]
    table = box(
        (tx, ty, 0.375),
        (0.45, 0.35, 0.375),
        yaw,
        Surface("immunohistochemistry"),
        Surface("colorwheel"),
    )
    px, py = -0.70 + j[1, 0], -0.40 + j[1, 1]
    ball = (1.30 + j[3, 0], -1.00 + j[3, 1]) if changed else (-0.50 + j[3, 0], 0.70 + j[3, 1])
    on_table = [] if changed else [
        Sphere((tx + j[2, 0], ty + j[2, 1], 0.75 + 0.3), 0.3, Surface("astronaut"))]
    added = box((-1.60, 1.40, 0.30), (0.30, 0.30, 0.30), 0.3, Surface("coffee"),
                Surface("rocket")) if changed else []
    return [
        *room,
        *table,
        *on_table,
        Sphere((*ball, 0.35), 0.35, Surface("coffee")),
        Cylinder((px, py), 0.25, 0.0, 1.0,
                 Surface("astronaut" if changed else "chelsea", repeat=(2.0, 1.0))),
        Disc((px, py, 1.0), 0.25, Surface("grass", (0.5, 0.9, 0.4))),
        *added,
    ]


def _frames(prims, poses, size, fov_x: float, background, samples: int) -> list[Frame]:
    """The views from ``poses``, in their order, ``FRAME_THREADS`` rendered at a time (a
    frame depends on its pose alone; numpy lets go of the GIL in its array loops)."""
    width, height = (size, size) if np.ndim(size) == 0 else size
    cams = [from_fov(int(width), int(height), fov_x, pose) for pose in poses]
    with ThreadPoolExecutor(FRAME_THREADS) as pool:
        images = list(pool.map(lambda cam: render(prims, cam, background, samples), cams))
    return [Frame(rgb, depth, cam) for (rgb, depth), cam in zip(images, cams, strict=True)]


def _orbit_pose(azimuth: float, elevation: float) -> np.ndarray:
    direction = np.array(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ]
    )
    return look_at(np.asarray(ORBIT_TARGET) + ORBIT_RADIUS * direction, ORBIT_TARGET)


def object_poses(n_train: int = 60, n_test: int = 8, seed: int = 0):
    """Camera-to-world poses ``(train, test)`` of the ``"object"`` scene (see :func:`object_scene`)."""
    rng = np.random.default_rng([seed, 1])
    lo, hi = ORBIT_ELEVATION
    phase = rng.uniform(0.0, 2 * np.pi)
    s = np.arange(n_train) / max(n_train, 1)  # [n_train] fraction of the orbit
    train = [
        _orbit_pose(
            phase + 2 * np.pi * f, 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.sin(4 * np.pi * f)
        )
        for f in s
    ]
    return train, _orbit_views(rng, n_test)


def _orbit_views(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``n`` orbit poses at uniform random azimuths and elevations in ORBIT_ELEVATION."""
    lo, hi = ORBIT_ELEVATION
    return [
        _orbit_pose(a, e)
        for a, e in zip(rng.uniform(0, 2 * np.pi, n), rng.uniform(lo, hi, n), strict=True)
    ]


def object_val_poses(n_val: int = N_VAL, seed: int = 0) -> list[np.ndarray]:
    """Validation poses of the ``"object"`` scene: drawn as its test views are, from
    the rng stream ``[seed, 1, VAL_STREAM]`` (the test views use ``[seed, 1]``)."""
    return _orbit_views(np.random.default_rng([seed, 1, VAL_STREAM]), n_val)


def object_scene(size=128, n_train: int = 60, n_test: int = 8, seed: int = 0,
                 n_val: int = N_VAL, samples: int = SAMPLES) -> Scene:
    """Object-centric scene seen from an orbit (see module docstring).

    size: image side in pixels (or ``(width, height)``); horizontal field of view
    ``OBJECT_FOV_X``. Training views go once around the object, azimuth advancing
    uniformly while elevation oscillates twice between the ``ORBIT_ELEVATION``
    limits; test views sit at random azimuths and elevations on the same sphere, and
    so do the ``n_val`` validation views (another random stream).
    """
    prims = object_primitives(seed)
    return _open_scene("object", prims, (*object_poses(n_train, n_test, seed),
                                         object_val_poses(n_val, seed)),
                       size, OBJECT_FOV_X, OBJECT_BACKGROUND, samples)


def _open_scene(name: str, prims, poses, size, fov_x: float, background, samples: int
                ) -> Scene:
    """A scene whose rays may hit nothing (they show ``background``, without depth):
    its train, test and validation ``poses`` rendered, its bounds the primitives'."""
    train, test, val = (_frames(prims, p, size, fov_x, background, samples) for p in poses)
    return Scene(name=name, train=train, test=test, bounds=bounds_of(prims),
                 background=background, val=val)


def _room_walk_pose(phi: float, radius_scale: float, height: float, yaw: float) -> np.ndarray:
    """Camera on the walk ellipse at angle ``phi``; gaze at ROOM_LOOK_TARGET turned by ``yaw``."""
    eye = np.array(
        [
            radius_scale * ROOM_WALK_RADII[0] * np.cos(phi),
            radius_scale * ROOM_WALK_RADII[1] * np.sin(phi),
            height,
        ]
    )
    to_target = ROOM_LOOK_TARGET - eye
    c, s = np.cos(yaw), np.sin(yaw)
    turned = np.array(
        [c * to_target[0] - s * to_target[1], s * to_target[0] + c * to_target[1], to_target[2]]
    )
    return look_at(eye, eye + turned)


def room_poses(n_train: int = 60, n_test: int = 8, seed: int = 0):
    """Camera-to-world poses ``(train, test)`` of the ``"room"`` scene (see :func:`room_scene`)."""
    rng = np.random.default_rng([seed, 2])
    phase = rng.uniform(0.0, 2 * np.pi)
    phis = phase + 2 * np.pi * np.arange(n_train) / max(n_train, 1)  # [n_train]
    train = [
        _room_walk_pose(p, 1.0, ROOM_WALK_HEIGHT + 0.12 * np.sin(3 * p), 0.6 * np.sin(2 * p))
        for p in phis
    ]
    return train, _room_walk_views(rng, n_test)


def _room_walk_views(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``n`` poses off the walk: 0.85x its radius, eye height 1.2 or 1.7, random gaze."""
    return [
        _room_walk_pose(p, 0.85, h, y)
        for p, h, y in zip(
            rng.uniform(0, 2 * np.pi, n),
            rng.choice([1.2, 1.7], n),
            rng.uniform(-0.8, 0.8, n),
            strict=True,
        )
    ]


def room_val_poses(n_val: int = N_VAL, seed: int = 0) -> list[np.ndarray]:
    """Validation poses of the ``"room"`` scene: drawn as its test views are, from the
    rng stream ``[seed, 2, VAL_STREAM]`` (the test views use ``[seed, 2]``)."""
    return _room_walk_views(np.random.default_rng([seed, 2, VAL_STREAM]), n_val)


def room_scene(size=128, n_train: int = 60, n_test: int = 8, seed: int = 0,
               n_val: int = N_VAL, samples: int = SAMPLES) -> Scene:
    """Room walkthrough (see module docstring); every pixel has valid depth.

    Training views walk once around the ellipse ``ROOM_WALK_RADII`` at about
    ``ROOM_WALK_HEIGHT``, gaze swinging up to +-34 degrees left and right of the room
    centre; test views are at 0.85x the radius, eye heights 1.2 or 1.7 and
    random gaze offsets up to +-45 degrees; the ``n_val`` validation views are drawn
    the same way from another random stream.
    """
    train, test = room_poses(n_train, n_test, seed)
    prims = room_primitives(seed)
    lo, hi = bounds_of(prims)
    return Scene(
        name="room",
        train=_frames(prims, train, size, ROOM_FOV_X, (0.0, 0.0, 0.0), samples),
        test=_frames(prims, test, size, ROOM_FOV_X, (0.0, 0.0, 0.0), samples),
        bounds=(lo, hi),
        val=_frames(prims, room_val_poses(n_val, seed), size, ROOM_FOV_X, (0.0, 0.0, 0.0),
                    samples),
    )


# (x along the path, side: +1 left (y > 0) / -1 right, half extents (x, y, z), the photo
# on the wall facing the street, the brick tint of the other walls). Walls only: the
# roofs are above every camera and the floors below the ground, so never seen.
WALK_HOUSES = (
    (5.0, 1, (2.0, 1.6, 1.8), "chelsea", (1.0, 0.75, 0.6)),
    (12.0, -1, (2.6, 1.8, 2.2), "astronaut", (0.8, 0.8, 0.95)),
    (20.0, 1, (2.4, 2.0, 2.8), "coffee", (0.95, 0.9, 0.7)),
    (27.0, -1, (2.2, 1.6, 1.9), "rocket", (0.9, 0.6, 0.6)),
    (34.0, 1, (2.8, 1.8, 2.4), "colorwheel", (0.7, 0.9, 0.8)),
)
WALK_TREES = ((8.0, -1), (15.0, 1), (23.0, -1), (30.0, 1), (38.0, -1))  # (x, side)
WALK_ROCKS = ((3.0, -1, 0.5), (17.0, -1, 0.7), (25.0, 1, 0.45), (31.5, -1, 0.6))  # (x, side, r)
WALK_LAMPS = ((9.5, 1), (21.0, -1))  # (x, side): a post with a lamp ball on top
# "walk-change" (vbgs.data.changing), its events along the second half of the path where
# the forward-looking frames see them longest: the rock taken away and the lamp post moved
# (their indices above; the post across the road and this far along x), the crate added
# on the left verge ((centre), (half extents)) and the house repainted (index, photo).
WALK_GONE_ROCK = 1
WALK_MOVED_LAMP, WALK_LAMP_MOVE = 1, 2.0
WALK_CRATE = ((28.5, -3.2, 0.45), (0.5, 0.45, 0.45))
WALK_REPAINT = (2, "camera")
# Far buildings, (centre x, centre y, half extents): beyond the end of the path, so
# they are seen from the first frame on at 40-55 units and come closer (depth > 30).
WALK_FAR = (
    (50.0, -13.0, (3.0, 3.0, 6.0), "immunohistochemistry"),
    (56.0, 7.0, (4.0, 3.0, 8.0), "camera"),
    (47.0, 19.0, (3.0, 4.0, 5.0), "astronaut"),
)
WALK_GROUND = ((-4.0, 66.0), 26.0, 1.8)  # ground x range, half width, half width of the road


def walk_primitives(seed: int = 0, length: float = WALK_LENGTH, changed: bool = False
                    ) -> list:
    """Primitives of the ``"walk"`` scene (of ``"walk-long"`` with ``length =
    WALK_LONG_LENGTH``); ``seed`` jitters every object's place (and a house's yaw) along
    the street. ``changed``: the walk after its change events (:mod:`vbgs.data.changing`;
    the first block only, :func:`_walk_block`): a rock taken away, a lamp post moved
    across the road, a crate added on the left verge and a house's street front
    repainted.

    A path ``length`` units long gets the street's objects repeated every ``WALK_BLOCK``
    units until they pass its end by as much as the walk's do (8 units), the ground
    and the far buildings moved out by ``length - WALK_LENGTH``. The walk's own
    primitives are drawn first, in its order and from its random stream, so at
    ``length = WALK_LENGTH`` they are the walk's to the bit and on a longer path its
    first block is the walk's street."""
    rng = np.random.default_rng(seed)
    beyond = length - WALK_LENGTH  # how much further the path goes than the walk's
    (x0, x1), half_width, road = WALK_GROUND
    x1 = x1 + beyond
    blocks = int(np.ceil((length + WALK_BLOCK - WALK_LENGTH) / WALK_BLOCK))  # 1 for the walk
    ground = x1 - x0  # the ground's length along x
    grass = Surface("grass", (0.75, 1.0, 0.6), (ground / 5.0, (half_width - road) / 5.0))
    prims = [  # the ground: a gravel road along x between two grass verges, all at z = 0
        Quad((x0, road, 0.0), (ground, 0.0, 0.0), (0.0, -2 * road, 0.0),
             Surface("gravel", (0.6, 0.6, 0.65), (ground / (2 * road), 1.0))),
        Quad((x0, half_width, 0.0), (ground, 0.0, 0.0), (0.0, road - half_width, 0.0), grass),
        Quad((x0, -road, 0.0), (ground, 0.0, 0.0), (0.0, road - half_width, 0.0), grass),
    ]
    prims += _walk_block(rng, 0, changed)
    for x, y, (hx, hy, hz), photo in WALK_FAR:
        dx, dy = rng.uniform(-1.0, 1.0, 2)
        facade = Surface(photo, (0.85, 0.85, 0.95), (1.0, 2.0))
        prims += box((x + beyond + dx, y + dy, hz), (hx, hy, hz), 0.0, facade, facade)[:4]
    for block in range(1, blocks):  # a longer path's street, after the walk's draws
        prims += _walk_block(rng, block)
    return prims


def _walk_block(rng: np.random.Generator, block: int, changed: bool = False) -> list:
    """The street's houses, trees, rocks and lamp posts moved ``block * WALK_BLOCK``
    units along x, each jittered by ``rng``; the house photos rotated by ``block``.
    ``changed``: the block after the walk's change events (:func:`walk_primitives`), every
    random draw made as without them, so all else is the same to the bit."""
    shift = block * WALK_BLOCK
    photos = [h[3] for h in WALK_HOUSES]
    prims = []
    for i, (x, side, (hx, hy, hz), _, tint) in enumerate(WALK_HOUSES):
        photo = photos[(i + block) % len(photos)]
        if changed and i == WALK_REPAINT[0]:
            photo = WALK_REPAINT[1]
        dx, dy = rng.uniform(-0.6, 0.6), rng.uniform(0.0, 0.8)
        yaw = rng.uniform(-0.15, 0.15)
        brick = Surface("brick", tint, (2.0, 1.0))
        street = Surface(photo, repeat=(1.0, 1.0))
        walls = [brick, street if side < 0 else brick, brick, street if side > 0 else brick]
        prims += box((x + shift + dx, side * (5.5 + hy + dy), hz), (hx, hy, hz), yaw, walls,
                     brick)[:4]
    for x, side in WALK_TREES:
        dx, dy = rng.uniform(-0.6, 0.6, 2)
        tx, ty = x + shift + dx, side * (3.3 + 0.3 * dy)
        prims += [
            Cylinder((tx, ty), 0.18, 0.0, 2.2, Surface("camera", (0.65, 0.45, 0.3), (2.0, 1.0))),
            Sphere((tx, ty, 2.9), 1.0, Surface("grass", (0.5, 0.9, 0.4), (3.0, 2.0))),
        ]
    for k, (x, side, r) in enumerate(WALK_ROCKS):
        dx, dy = rng.uniform(-0.6, 0.6, 2)
        if changed and k == WALK_GONE_ROCK:  # taken away
            continue
        prims.append(Sphere((x + shift + dx, side * (3.0 + 0.4 * dy), 0.5 * r), r,
                            Surface("gravel", (0.8, 0.78, 0.75), (2.0, 1.0))))
    for k, (x, side) in enumerate(WALK_LAMPS):
        dx = rng.uniform(-0.6, 0.6)
        if changed and k == WALK_MOVED_LAMP:  # moved across the road, a little further on
            x, side = x + WALK_LAMP_MOVE, -side
        prims += [
            Cylinder((x + shift + dx, side * 2.4), 0.08, 0.0, 2.8,
                     Surface("rocket", (0.5, 0.5, 0.55))),
            Sphere((x + shift + dx, side * 2.4, 2.95), 0.2, Surface("colorwheel")),
        ]
    if changed:  # added on the left verge
        centre, half = WALK_CRATE
        prims += box(centre, half, 0.4, Surface("coffee"), Surface("astronaut"))
    return prims


def _walk_path(s, length: float = WALK_LENGTH):
    """Point ``(x, y)`` and heading (radians from +x) of the path ``length`` units long
    at fraction ``s``: it weaves ``WALK_WEAVE_PERIODS`` times every ``WALK_LENGTH`` units."""
    periods = WALK_WEAVE_PERIODS * (length / WALK_LENGTH)
    phase = 2 * np.pi * periods * s
    x, y = length * s, WALK_WEAVE * np.sin(phase)
    slope = WALK_WEAVE * 2 * np.pi * periods / length * np.cos(phase)  # dy/dx
    return x, y, np.arctan(slope)


def _walk_pose(s: float, lateral: float, height: float, yaw: float,
               length: float = WALK_LENGTH) -> np.ndarray:
    """Camera at fraction ``s`` of the path ``length`` units long, ``lateral`` units to its
    left, at ``height``; gaze along the path turned ``yaw`` radians to the left, dipped
    ``WALK_PITCH``."""
    x, y, heading = _walk_path(s, length)
    eye = np.array([x - lateral * np.sin(heading), y + lateral * np.cos(heading), height])
    a = heading + yaw
    gaze = np.array([np.cos(a) * np.cos(WALK_PITCH), np.sin(a) * np.cos(WALK_PITCH),
                     -np.sin(WALK_PITCH)])
    return look_at(eye, eye + gaze)


def walk_poses(n_train: int = 60, n_test: int = 8, seed: int = 0,
               length: float = WALK_LENGTH):
    """Camera-to-world poses ``(train, test)`` of the ``"walk"`` scene (see :func:`walk_scene`),
    on a path ``length`` units long (the gaze wanders at the walk's rate per unit)."""
    rng = np.random.default_rng([seed, 3])
    phase = rng.uniform(0.0, 2 * np.pi)
    s = np.arange(n_train) / max(n_train - 1, 1)  # [n_train] from the start to the end
    periods = WALK_WANDER_PERIODS * (length / WALK_LENGTH)
    yaw = WALK_WANDER * np.sin(2 * np.pi * periods * s + phase)
    train = [_walk_pose(f, 0.0, WALK_EYE, w, length) for f, w in zip(s, yaw, strict=True)]
    return train, _walk_views(rng, n_test, length)


def _walk_views(rng: np.random.Generator, n: int, length: float = WALK_LENGTH
                ) -> list[np.ndarray]:
    """``n`` poses off the path ``length`` units long: one in each of ``n`` equal stretches
    of it (so they cover the whole path), 0.2-0.6 units to its left or right, eye height
    1.5 +- 0.3, gaze within +-0.5 rad of the path's heading. They come in the order of
    stretches 0, 2, 4, ..., then 1, 3, 5, ...: the first half of them spans the whole
    path too (``fit-scene --save`` draws the first four)."""
    s = (np.arange(n) + rng.uniform(0.0, 1.0, n)) / max(n, 1)
    lateral = rng.choice([-1.0, 1.0], n) * rng.uniform(0.2, 0.6, n)
    height = WALK_EYE + rng.uniform(-0.3, 0.3, n)
    yaw = rng.uniform(-0.5, 0.5, n)
    poses = [_walk_pose(*v, length) for v in zip(s, lateral, height, yaw, strict=True)]
    return [poses[i] for i in np.r_[0:n:2, 1:n:2]]


def walk_val_poses(n_val: int = N_VAL, seed: int = 0, length: float = WALK_LENGTH
                   ) -> list[np.ndarray]:
    """Validation poses of the ``"walk"`` scene: drawn as its test views are, from the
    rng stream ``[seed, 3, VAL_STREAM]`` (the test views use ``[seed, 3]``)."""
    return _walk_views(np.random.default_rng([seed, 3, VAL_STREAM]), n_val, length)


def walk_scene(size=128, n_train: int = 60, n_test: int = 8, seed: int = 0,
               n_val: int = N_VAL, samples: int = SAMPLES, length: float = WALK_LENGTH,
               name: str = "walk") -> Scene:
    """Open walk down a street (see module docstring); the sky has no depth.

    Training views walk once forward along the path, ``length`` units from x = 0
    (``WALK_LENGTH``; ``"walk-long"``: ``WALK_LONG_LENGTH``), never coming back, at eye
    height ``WALK_EYE``, gaze wandering up to ``WALK_WANDER`` rad left and right of the
    path's heading; test views are spread along the whole path, off it by 0.2-0.6
    units, eye heights 1.2-1.8 and gaze up to +-0.5 rad from the heading; the ``n_val``
    validation views are drawn the same way from another random stream.
    """
    prims = walk_primitives(seed, length)
    return _open_scene(name, prims, (*walk_poses(n_train, n_test, seed, length),
                                     walk_val_poses(n_val, seed, length)),
                       size, WALK_FOV_X, WALK_SKY, samples)


def walk_long_scene(size=128, n_train: int = WALK_LONG_FRAMES, n_test: int = 8,
                    seed: int = 0, n_val: int = N_VAL, samples: int = SAMPLES) -> Scene:
    """The walk's street continued for ``WALK_LONG_LENGTH`` units (see the module
    docstring): ``n_train`` frames along it, ``WALK_LONG_FRAMES`` at the walk's step."""
    return walk_scene(size, n_train, n_test, seed, n_val, samples, WALK_LONG_LENGTH,
                      "walk-long")


def render_views(name: str, poses, size=128, seed: int = 0, samples: int = SAMPLES
                 ) -> list[Frame]:
    """Frames of synthetic scene ``name`` seen from the given camera-to-world ``poses``
    (``samples`` rays per pixel side, see :data:`SAMPLES`)."""
    fov, background = _VIEWING[name.removesuffix("-change").removesuffix("-long")]
    return _frames(scene_primitives(name, seed), poses, size, fov, background, samples)


# Each scene's horizontal field of view and the colour of rays that hit nothing.
_VIEWING = {"object": (OBJECT_FOV_X, OBJECT_BACKGROUND), "room": (ROOM_FOV_X, (0.0, 0.0, 0.0)),
            "walk": (WALK_FOV_X, WALK_SKY)}


def changing_scene(base: str, size=128, n_train: int = 60, n_test: int = 8, seed: int = 0,
                   n_val: int = N_VAL, samples: int = SAMPLES) -> Scene:
    """The scene ``base`` ("object", "room" or "walk") whose world changes between two
    laps of its path (:mod:`vbgs.data.changing`): ``n_train`` frames in all, the first
    half before the change; test and validation views of the final state,
    ``first_state`` the test views before it."""
    bases = {
        "object": (object_primitives, object_poses, object_val_poses),
        "room": (room_primitives, room_poses, room_val_poses),
        "walk": (walk_primitives, walk_poses, walk_val_poses),
    }
    if base not in bases:
        raise ValueError(f"no changing version of {base!r}: use {', '.join(bases)}")
    primitives, poses, val_poses = bases[base]
    fov, background = _VIEWING[base]

    def frames(prims, at):
        return _frames(prims, at, size, fov, background, samples)

    scene = two_laps(f"{base}-change", primitives(seed), primitives(seed, changed=True),
                     poses, val_poses, n_train, n_test, n_val, seed, frames)
    return scene._replace(background=background)


SCENES = {"object": object_scene, "room": room_scene, "walk": walk_scene,
          "walk-long": walk_long_scene,
          "object-change": partial(changing_scene, "object"),
          "room-change": partial(changing_scene, "room"),
          "walk-change": partial(changing_scene, "walk")}
PRIMITIVES = {"object": object_primitives, "room": room_primitives, "walk": walk_primitives,
              "walk-long": lambda seed=0: walk_primitives(seed, WALK_LONG_LENGTH),
              "object-change": lambda seed=0: object_primitives(seed, changed=True),
              "room-change": lambda seed=0: room_primitives(seed, changed=True),
              "walk-change": lambda seed=0: walk_primitives(seed, changed=True)}


def make_scene(name: str, **kw) -> Scene:
    """Build the synthetic scene ``name`` (a key of :data:`SCENES`) with keyword arguments ``kw``."""
    if name not in SCENES:
        raise ValueError(f"unknown synthetic scene {name!r}; known scenes: {', '.join(SCENES)}")
    return SCENES[name](**kw)


def scene_primitives(name: str, seed: int = 0) -> list:
    """The analytic primitives behind synthetic scene ``name`` (for exactness checks)."""
    if name not in PRIMITIVES:
        raise ValueError(f"unknown synthetic scene {name!r}; known scenes: {', '.join(PRIMITIVES)}")
    return PRIMITIVES[name](seed)
