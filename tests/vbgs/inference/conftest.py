"""Fixtures shared by the inference tests."""

import jax
import pytest

from vbgs import mapping
from vbgs.data.formats import load_scene


@pytest.fixture(scope="session")
def object_map():
    """The object at 48 px: a 3000-component map grown on eight frames, and the scene
    (its ninth training frame is the next to learn)."""
    scene = load_scene("object", size=48, n_train=12, n_test=1, seed=0)
    config = mapping.Config(components=3000)
    state = mapping.init(config, key=jax.random.key(0))
    for frame in scene.train[:8]:
        state, _ = mapping.update(state, frame, config)
    return state, scene
