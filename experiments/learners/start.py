"""Where a scene learner starts: :func:`scene_prior` (the oracle starts ``data`` and
``random`` of :mod:`experiments.init_schemes`, from every training frame) and the
constants of the ``stream`` start. The key is ``jax.random.key(task.seed)`` for both
learners, so VBGS and the gradient baseline start from the same components.
"""

from __future__ import annotations

import jax
import numpy as np

from experiments.protocol import frame_points
from vbgs.inference import model
from vbgs.data.scene import Scene


# The share of the capacity K a 3-D stream's first frame gets (it fixes the cell side
# of :mod:`vbgs.inference.grow`); measured on the object scene, see the README.
FIRST_FRAME_SHARE = 0.1
# Share of the empty slots a frame may spend refining ground already covered (finer
# cells, see vbgs.inference.grow); what is left stays for new ground in later frames.
REFINE_SHARE = 0.05


def init_key(task) -> jax.Array:
    """The key every learner initialises with."""
    return jax.random.key(task.seed)


def scene_prior(task, scene: Scene) -> model.Mixture:
    """The starting prior from the points of every training frame (data or random
    scheme) in the scene's bounds."""
    xyz, rgb = (np.concatenate(a) for a in zip(*map(frame_points, scene.train), strict=True))
    return model.init(xyz, rgb, task.components, key=init_key(task), scheme=task.init,
                      config=task.prior, bounds=scene.bounds)
