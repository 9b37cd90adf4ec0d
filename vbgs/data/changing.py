"""Synthetic scenes that change while they are streamed: the harness of continual
learning's second half, forgetting what is gone while keeping what is still there.

``"object-change"``, ``"room-change"`` and ``"walk-change"`` are the object, the room and
the walk (:mod:`vbgs.data.synthetic`) walked twice along the training path, ``n_train /
2`` frames a lap (the walk's path twice from its start, forward). The first lap sees the
scene as it was; before the second, every change event happens at once (the frame index
is the scene's ``changes``):

* object: the sphere is taken away, the crate moved onto its place, a new ball added
  where the platform was bare, and the cylinder's texture replaced;
* room: the ball on the table is taken away, the ball on the floor moved across the
  room, a crate added by a wall, and the stool's texture replaced;
* walk: a rock is taken away, a lamp post moved across the road, a crate added on the
  left verge, and a house's street front repainted, all along the second half of the
  path, which the forward-looking frames see from the start.

The test and validation views show the final state; ``Scene.first_state`` holds the
test views rendered in the first state (the same poses), so a run can say what the map
kept of the world as it was and score the pixels that changed apart from those that did
not (:func:`changed_pixels`). Everything is seeded as the static scenes are: the first
state is the static scene itself, to the bit.
"""

from __future__ import annotations

import numpy as np

from vbgs.data.raycast import bounds_of
from vbgs.data.scene import Frame, Scene

# A pixel changed when its colour moved more than this (any channel, in [0, 1]) or its
# depth by more than this share of the depth between the two states' test views.
COLOUR_CHANGE = 2.0 / 255.0
DEPTH_CHANGE = 1e-3


def two_laps(name: str, first: list, final: list, poses, val_poses, n_train: int,
             n_test: int, n_val: int, seed: int, frames) -> Scene:
    """A scene walked twice along its path, ``first`` primitives the first lap and
    ``final`` the second (see the module docstring); ``poses(n_train, n_test, seed)`` and
    ``val_poses(n_val, seed)`` its base scene's pose functions, ``frames(prims, poses)``
    its renderer. ``n_train`` frames in all, at least 2."""
    if n_train < 2:
        raise ValueError(f"a changing scene walks its path twice: n_train must be at least "
                         f"2, got {n_train}")
    lap = n_train // 2
    path, test = poses(lap, n_test, seed)
    second = poses(n_train - lap, n_test, seed)[0]
    (lo0, hi0), (lo1, hi1) = bounds_of(first), bounds_of(final)
    return Scene(name=name, train=frames(first, path) + frames(final, second),
                 test=frames(final, test), bounds=(np.minimum(lo0, lo1), np.maximum(hi0, hi1)),
                 val=frames(final, val_poses(n_val, seed)), first_state=frames(first, test),
                 changes=(lap,))


def changed_pixels(first: Frame, final: Frame) -> np.ndarray:
    """``[h, w]`` bool: where the two states of one view differ in colour or depth."""
    colour = np.abs(np.asarray(final.rgb) - np.asarray(first.rgb)).max(-1) > COLOUR_CHANGE
    d0, d1 = np.asarray(first.depth, np.float64), np.asarray(final.depth, np.float64)
    depth = np.abs(d1 - d0) > DEPTH_CHANGE * np.maximum(np.maximum(d0, d1), 1e-30)
    return colour | depth


def from_frame(scene: Scene, first: int) -> Scene:
    """``scene`` streamed from training frame ``first`` on: a fresh map of what those
    frames show (after a changing scene's last change, the world as it is now); its change
    frames counted from there, those before it dropped."""
    if not 0 <= first < len(scene.train):
        raise ValueError(f"from_frame must lie within the {len(scene.train)} training "
                         f"frames (0 to {len(scene.train) - 1}), got {first}")
    return scene._replace(train=scene.train[first:],
                          changes=tuple(c - first for c in scene.changes if c > first))
