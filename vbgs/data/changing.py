"""Synthetic scenes that change while they are streamed: the harness of continual
learning's second half, forgetting what is gone while keeping what is still there.

``"object-change"`` and ``"room-change"`` are the object and the room
(:mod:`vbgs.data.synthetic`) walked twice along the training path, ``n_train / 2``
frames a lap. The first lap sees the scene as it was; before the second, every change
event happens at once (the frame index is the scene's ``changes``):

* object: the sphere is taken away, the crate moved onto its place, a new ball added
  where the platform was bare, and the cylinder's texture replaced;
* room: the ball on the table is taken away, the ball on the floor moved across the
  room, a crate added by a wall, and the stool's texture replaced.

The test and validation views show the final state; ``Scene.first_state`` holds the
test views rendered in the first state (the same poses), so a run can say what the map
kept of the world as it was and score the pixels that changed apart from those that did
not (:func:`changed_pixels`). Everything is seeded as the static scenes are: the first
state is the static scene itself, to the bit.
"""

from __future__ import annotations

import numpy as np

from vbgs.data.scene import Frame, Scene
from vbgs.data.synthetic import (
    N_VAL,
    OBJECT_BACKGROUND,
    OBJECT_FOV_X,
    ROOM_FOV_X,
    SAMPLES,
    _frames,
    object_poses,
    object_primitives,
    object_val_poses,
    room_poses,
    room_primitives,
    room_val_poses,
)
from vbgs.data.raycast import bounds_of

# A pixel changed when its colour moved more than this (any channel, in [0, 1]) or its
# depth by more than this share of the depth between the two states' test views.
COLOUR_CHANGE = 2.0 / 255.0
DEPTH_CHANGE = 1e-3

_BASES = {
    "object": (object_primitives, object_poses, object_val_poses, OBJECT_FOV_X,
               OBJECT_BACKGROUND),
    "room": (room_primitives, room_poses, room_val_poses, ROOM_FOV_X, (0.0, 0.0, 0.0)),
}


def changing_scene(base: str, size=128, n_train: int = 60, n_test: int = 8, seed: int = 0,
                   n_val: int = N_VAL, samples: int = SAMPLES) -> Scene:
    """The scene ``base`` ("object" or "room") changing after the first of two laps (see
    the module docstring); ``n_train`` frames in all, at least 2."""
    if base not in _BASES:
        raise ValueError(f"no changing version of {base!r}: use one of {', '.join(_BASES)}")
    if n_train < 2:
        raise ValueError(f"a changing scene walks its path twice: n_train must be at least "
                         f"2, got {n_train}")
    primitives, poses, val_poses, fov, background = _BASES[base]
    first, final = primitives(seed), primitives(seed, changed=True)
    lap = n_train // 2
    path, test = poses(lap, n_test, seed)
    second = poses(n_train - lap, n_test, seed)[0]

    def frames(prims, at):
        return _frames(prims, at, size, fov, background, samples)

    lo0, hi0 = bounds_of(first)
    lo1, hi1 = bounds_of(final)
    return Scene(name=f"{base}-change", train=frames(first, path) + frames(final, second),
                 test=frames(final, test), bounds=(np.minimum(lo0, lo1), np.maximum(hi0, hi1)),
                 background=background, val=frames(final, val_poses(n_val, seed)),
                 first_state=frames(first, test), changes=(lap,))


def changed_pixels(first: Frame, final: Frame) -> np.ndarray:
    """``[h, w]`` bool: where the two states of one view differ in colour or depth."""
    colour = np.abs(np.asarray(final.rgb) - np.asarray(first.rgb)).max(-1) > COLOUR_CHANGE
    d0, d1 = np.asarray(first.depth, np.float64), np.asarray(final.depth, np.float64)
    depth = np.abs(d1 - d0) > DEPTH_CHANGE * np.maximum(np.maximum(d0, d1), 1e-30)
    return colour | depth
