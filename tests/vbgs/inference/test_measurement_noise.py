"""Measured points: noise along the rays, deconvolved in the M-step and convolved in the
E-step (expfam.Stats.sum_noise, candidates.candidate_logits with ray)."""

import jax
import numpy as np
import pytest

from vbgs.inference import expfam, model, stepper

SIGMA = 0.05  # the noise along the rays (straight down onto the plane z = 0)


def noisy_plane(seed, n=4000):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1, 1, (n, 2))
    xyz = np.c_[xy, SIGMA * rng.standard_normal(n)].astype(np.float32)
    rgb = np.full((n, 3), 0.5, np.float32)
    ray = np.tile([0.0, 0.0, SIGMA], (n, 1)).astype(np.float32)
    return xyz, rgb, ray


@pytest.fixture(scope="module")
def plane():
    xyz, rgb, ray = noisy_plane(0)
    prior = model.init(xyz, rgb, 16, key=jax.random.key(0), scheme="data")
    return prior, xyz, rgb, ray


def thickness(state):
    """Per used component, the expected standard deviation along the plane's normal."""
    cov = np.asarray(expfam.niw_expected_covariance(state.posterior.space))
    used = np.asarray(state.stats.count) > 50
    return np.sqrt(cov[used][:, 2, 2])


def test_a_noisy_plane_gives_components_as_thin_as_the_plane(plane):
    """Exact-data statistics make each component as thick as the noise (0.05); with the
    noise along the rays deconvolved they are as thin as the plane allows: the prior's
    floor (about 0.01-0.03 here), whatever the noise."""
    prior, xyz, rgb, ray = plane
    blurred, _ = model.update(model.start(prior), xyz, rgb, estep="sparse")
    sharp, _ = model.update(model.start(prior), xyz, rgb, estep="sparse", ray=ray)
    assert np.median(thickness(blurred)) == pytest.approx(SIGMA, rel=0.15)
    assert np.median(thickness(sharp)) < 0.4 * SIGMA
    # the means stay on the plane and the in-plane spread is untouched
    means = np.asarray(sharp.posterior.space.mean + sharp.posterior.origin)
    used = np.asarray(sharp.stats.count) > 50
    assert np.abs(means[used, 2]).max() < 0.01
    cov_b = np.asarray(expfam.niw_expected_covariance(blurred.posterior.space))[used]
    cov_s = np.asarray(expfam.niw_expected_covariance(sharp.posterior.space))[used]
    np.testing.assert_allclose(cov_s[:, 0, 0], cov_b[:, 0, 0], rtol=0.05)


def test_deconvolved_scales_stay_positive_definite(plane):
    """Few points can scatter less than their noise (here 4 x the noise they show): the
    share taken off keeps every scale at least 1 - NOISE_SHARE_MAX of the undeconvolved
    one, positive definite."""
    prior, xyz, rgb, ray = plane
    state, _ = model.update(model.start(prior), xyz[:40], rgb[:40], estep="sparse",
                            ray=4 * ray[:40])
    plain, _ = model.update(model.start(prior), xyz[:40], rgb[:40], estep="sparse")
    deconvolved = np.asarray(state.posterior.space.scale, np.float64)
    before = np.asarray(plain.posterior.space.scale, np.float64)
    assert np.linalg.eigvalsh(deconvolved)[:, 0].min() > 0
    thinnest, was = np.linalg.eigvalsh(deconvolved)[:, 0], np.linalg.eigvalsh(before)[:, 0]
    assert (thinnest < 0.5 * was).any()  # the noise was taken off...
    # ...but never all of it (the two fits' responsibilities differ a little: half of it)
    assert (thinnest > 0.5 * (1 - expfam.NOISE_SHARE_MAX) * was).all()


def test_a_noisy_stream_equals_one_batch_in_any_order(plane):
    """Under prior assignment the noise moments add like the others: streamed in four
    batches, forwards or backwards, through the compiled stepper, the statistics equal
    one batch's."""
    prior, xyz, rgb, ray = plane
    batch, _ = model.update(model.start(prior), xyz, rgb, estep="sparse", ray=ray)
    step = stepper.Stepper(prior, estep="sparse", search="kdtree")
    for order in (range(4), reversed(range(4))):
        state = model.start(prior)
        state = state._replace(stats=expfam.zero_stats(16, 3, noisy=True))
        for i in order:
            rows = slice(1000 * i, 1000 * (i + 1))
            state, _ = step(state, xyz[rows], rgb[rows], ray[rows])
        for a, b in zip(state.stats, batch.stats, strict=True):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=2e-3)


def test_noise_is_refused_where_it_is_not_modelled(plane):
    prior, xyz, rgb, ray = plane
    with pytest.raises(ValueError, match="estep='sparse'"):
        model.update(model.start(prior), xyz, rgb, estep="dense", ray=ray)
    with pytest.raises(ValueError, match=r"ray must be finite \[n=4000"):
        model.update(model.start(prior), xyz, rgb, estep="sparse", ray=ray[:10])
