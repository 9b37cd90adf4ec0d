"""Where a scene learner starts: :func:`scene_prior` (the oracle starts ``data`` and
``random`` of :mod:`experiments.tasks.init_schemes`, from every training frame); the ``stream``
start grows by :class:`vbgs.mapping.GrowthConfig` (the task's ``growth``). The key is ``jax.random.key(task.seed)`` for both
learners, so VBGS and the gradient baseline start from the same components.
"""

from __future__ import annotations

import jax
import numpy as np

from experiments.tasks.protocol import frame_points
from vbgs.data.scene import Scene
from vbgs.inference import model


def init_key(task) -> jax.Array:
    """The key every learner initialises with."""
    return jax.random.key(task.seed)


def scene_prior(task, scene: Scene) -> model.Mixture:
    """The starting prior from the points of every training frame (data or random
    scheme) in the scene's bounds."""
    xyz, rgb = (np.concatenate(a) for a in zip(*map(frame_points, scene.train), strict=True))
    return model.init(xyz, rgb, task.components, key=init_key(task), scheme=task.init,
                      config=task.prior, bounds=scene.bounds)
