"""Synthetic RGB-D scenes with exact ground truth, for any camera.

Two scenes are ray cast analytically (:mod:`vbgs.data.raycast`) from textured
primitives, so colour and z-depth are exact up to float32 rounding:

* ``"object"``: object-centric, like NeRF-synthetic. A textured platform
  (top at z = 0) carrying a sphere, a box and a capped cylinder, all inside
  about [-1, 1]^3, seen from an orbit of radius ``ORBIT_RADIUS`` around
  ``ORBIT_TARGET``. Pixels that hit nothing have depth 0 (invalid) and rgb
  ``OBJECT_BACKGROUND`` (white, as in NeRF-synthetic).
* ``"room"``: a closed 6 x 5 x 2.6 room (floor at z = 0) with a photo on each
  wall, tiled floor and ceiling, a table with a ball on it, a ball on the floor
  and a stool, seen along a walkthrough inside it. Every pixel has valid depth.

World axes: z up, units are metres-like scene units. Training views follow a
continuous closed path (frame i and i + 1 are neighbouring views, so streaming
order matters); test views are drawn off that path under the same ``seed``;
validation views (:func:`object_val_poses`, :func:`room_val_poses`) are drawn the way
test views are, from a separate random stream (``[seed, scene tag, VAL_STREAM]``),
so adding them leaves the training and test views bit-identical.
``seed`` also jitters object placement, so different seeds give different scenes
and the same seed gives bit-identical frames.
"""

from __future__ import annotations

import numpy as np

from vbgs.data.raycast import Cylinder, Disc, Sphere, Surface, bounds_of, box, render
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
VAL_STREAM = 3  # third entry of the validation views' rng seed (train/test use [seed, tag])
N_VAL = 4  # validation views per synthetic scene by default
# Rays per pixel side: a pixel's colour is the mean of SAMPLES x SAMPLES rays spread
# over its area (a box filter, as a camera integrates light and as NeRF-synthetic's
# renders are anti-aliased); its depth is the centre ray's. With one ray per pixel
# every silhouette is a hard, aliased step that no renderer with smooth footprints
# (Gaussian splats) can reproduce: on the object scene two thirds of VBGS's squared
# error sat in the pixels beside depth edges. ``samples=1`` gives the aliased frames.
SAMPLES = 3


def object_primitives(seed: int = 0) -> list:
    """Primitives of the ``"object"`` scene; ``seed`` jitters placement and yaw."""
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
    crate = box(
        (-0.40 + jy[0], 0.30 + jy[1], 0.30),
        (0.30, 0.30, 0.30),
        yaw,
        Surface("coffee"),
        Surface("rocket"),
    )
    cap = Surface("immunohistochemistry")
    return [
        *platform,
        *crate,
        Sphere((sx, sy, 0.45), 0.45, Surface("astronaut")),
        Cylinder((cx, cy), 0.22, 0.0, 0.7, Surface("chelsea", repeat=(2.0, 1.0))),
        Disc((cx, cy, 0.7), 0.22, cap),
        Disc((cx, cy, 0.0), 0.22, cap),
    ]


def room_primitives(seed: int = 0) -> list:
    """Primitives of the ``"room"`` scene; ``seed`` jitters the furniture."""
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
    return [
        *room,
        *table,
        Sphere((tx + j[2, 0], ty + j[2, 1], 0.75 + 0.3), 0.3, Surface("astronaut")),
        Sphere((-0.50 + j[3, 0], 0.70 + j[3, 1], 0.35), 0.35, Surface("coffee")),
        Cylinder((px, py), 0.25, 0.0, 1.0, Surface("chelsea", repeat=(2.0, 1.0))),
        Disc((px, py, 1.0), 0.25, Surface("grass", (0.5, 0.9, 0.4))),
    ]


def _frames(prims, poses, size, fov_x: float, background, samples: int) -> list[Frame]:
    width, height = (size, size) if np.ndim(size) == 0 else size
    frames = []
    for pose in poses:
        cam = from_fov(int(width), int(height), fov_x, pose)
        rgb, depth = render(prims, cam, background, samples)
        frames.append(Frame(rgb, depth, cam))
    return frames


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
    train, test = object_poses(n_train, n_test, seed)
    prims = object_primitives(seed)
    return Scene(
        name="object",
        train=_frames(prims, train, size, OBJECT_FOV_X, OBJECT_BACKGROUND, samples),
        test=_frames(prims, test, size, OBJECT_FOV_X, OBJECT_BACKGROUND, samples),
        bounds=bounds_of(prims),
        background=OBJECT_BACKGROUND,
        val=_frames(prims, object_val_poses(n_val, seed), size, OBJECT_FOV_X, OBJECT_BACKGROUND,
                    samples),
    )


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


def render_views(name: str, poses, size=128, seed: int = 0, samples: int = SAMPLES
                 ) -> list[Frame]:
    """Frames of synthetic scene ``name`` seen from the given camera-to-world ``poses``
    (``samples`` rays per pixel side, see :data:`SAMPLES`)."""
    fov, background = {"object": (OBJECT_FOV_X, OBJECT_BACKGROUND),
                       "room": (ROOM_FOV_X, (0.0, 0.0, 0.0))}[name]
    return _frames(scene_primitives(name, seed), poses, size, fov, background, samples)


SCENES = {"object": object_scene, "room": room_scene}
PRIMITIVES = {"object": object_primitives, "room": room_primitives}


def make_scene(name: str, **kw) -> Scene:
    """Build the synthetic scene ``name`` ("object" or "room") with keyword arguments ``kw``."""
    if name not in SCENES:
        raise ValueError(f"unknown synthetic scene {name!r}; known scenes: {', '.join(SCENES)}")
    return SCENES[name](**kw)


def scene_primitives(name: str, seed: int = 0) -> list:
    """The analytic primitives behind synthetic scene ``name`` (for exactness checks)."""
    if name not in PRIMITIVES:
        raise ValueError(f"unknown synthetic scene {name!r}; known scenes: {', '.join(PRIMITIVES)}")
    return PRIMITIVES[name](seed)
