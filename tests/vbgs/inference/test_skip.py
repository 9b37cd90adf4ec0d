"""Skipping well-explained points (vbgs.inference.skip): the margin is in nats from the peak."""

import jax
import numpy as np
import pytest

from vbgs.inference import model, skip
from vbgs.inference.expfam import niw_expected_precision


@pytest.fixture(scope="module")
def fitted():
    rng = np.random.default_rng(0)
    centres = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    xyz = (centres[rng.integers(0, 3, 600)] + rng.normal(0, 0.05, (600, 3))).astype(np.float32)
    rgb = np.full((600, 3), 0.5, np.float32)
    prior = model.init(xyz, rgb, 3, key=jax.random.key(0), scheme="data")
    prior = prior._replace(space=prior.space._replace(mean=jax.numpy.asarray(centres) - prior.origin))
    state, _ = model.update(model.start(prior), xyz, rgb, assign="prior")
    return state


def explained(state, xyz, rgb, margin, min_count=skip.MIN_COUNT):
    return skip.well_explained(state.posterior, state.stats.count, np.float32(xyz),
                               np.float32(rgb), margin=margin, colour_noise=0.05,
                               min_count=min_count)


def test_a_point_at_a_component_peak_is_explained_and_a_far_one_is_not(fitted):
    q = fitted.posterior
    at_peak = np.asarray(q.space.mean + q.origin)  # each component's own means
    colours = np.asarray(q.colour.mean)
    assert explained(fitted, at_peak, colours, margin=1e-3).all()
    assert not explained(fitted, at_peak + 5.0, colours, margin=10.0).any()
    assert not explained(fitted, at_peak, colours, margin=0.0, min_count=1e9).any()


def test_the_margin_is_half_the_squared_mahalanobis_distance(fitted):
    """Moving a point by 3 expected standard deviations along x costs 4.5 nats: kept
    at margin 4, skipped at margin 5 (the colour matches, the mean is certain enough)."""
    q = fitted.posterior
    prec = np.asarray(niw_expected_precision(q.space))[0]
    step = 3.0 / np.sqrt(prec[0, 0])
    point = np.asarray(q.space.mean + q.origin)[:1] + np.float32([[step, 0, 0]])
    colour = np.asarray(q.colour.mean)[:1]
    assert not explained(fitted, point, colour, margin=4.0)[0]
    assert explained(fitted, point, colour, margin=5.0)[0]


def test_bad_margin_is_refused(fitted):
    with pytest.raises(ValueError, match="skip margin"):
        explained(fitted, np.zeros((1, 3)), np.zeros((1, 3)), margin=-1.0)
