"""Random initialisation draws component colours from the data's own colours."""

import jax
import numpy as np

from vbgs.inference import model


def test_random_init_colours_are_colours_of_the_data():
    rng = np.random.default_rng(0)
    xyz = rng.uniform(0, 1, (1000, 3)).astype(np.float32)
    red, blue = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    rgb = np.where(rng.uniform(size=(1000, 1)) < 0.3, red, blue).astype(np.float32)
    prior = model.init(xyz, rgb, 200, key=jax.random.key(1), scheme="random")
    colours = np.asarray(prior.colour.mean)  # [200, 3]
    is_red, is_blue = (np.all(colours == c, axis=1) for c in (red, blue))
    assert np.all(is_red | is_blue)  # no purple: the colour box's corners and inside are not drawn
    assert 0.15 < is_red.mean() < 0.45  # in the data's proportion (0.3)
    again = model.init(xyz, rgb, 200, key=jax.random.key(1), scheme="random")
    np.testing.assert_array_equal(np.asarray(again.colour.mean), colours)  # the key fixes them
