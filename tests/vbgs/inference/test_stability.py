"""Numerical stress: precision, far-off coordinates, degenerate and tiny images."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.data.images import image_to_points, load_image
from vbgs.inference import model
from vbgs.inference.fit import fit
from vbgs.render.image import expected_colour, render_image
from vbgs.render.metrics import psnr


def _fit(img, k, *, offset=0.0, dtype=np.float32, iters=5, scheme="data"):
    uv, rgb = image_to_points(img)
    uv, rgb = (uv + offset).astype(dtype), rgb.astype(dtype)
    prior = model.init(uv, rgb, k, key=jax.random.key(0), scheme=scheme)
    post, info = fit(prior, uv, rgb, iters=iters, key=jax.random.key(1))
    out = np.asarray(expected_colour(post, uv)).reshape(img.shape)
    return post, info, out


@pytest.fixture(scope="module")
def small():
    return load_image("coffee", 32)


@pytest.fixture(scope="module")
def near(small):
    """The float32 fit of ``small`` at its own coordinates (two tests' reference)."""
    return _fit(small, 300)


def test_float32_matches_float64(small, near):
    _, _, out32 = near
    with jax.enable_x64(True):
        post64, _, out64 = _fit(small, 300, dtype=np.float64)
        assert post64.alpha.dtype == jnp.float64
    assert np.isfinite(out32).all()
    assert abs(psnr(out32, small) - psnr(out64, small)) < 0.1


def test_coordinates_far_from_origin(small, near):
    _, _, near = near
    post, info, far = _fit(small, 300, offset=1e4)
    assert np.isfinite(far).all() and np.isfinite(info.elbo).all()
    assert abs(psnr(far, small) - psnr(near, small)) < 0.2
    assert np.abs(np.asarray(post.origin) - (1e4 + 16)).max() < 1e-3


def test_constant_image_is_reproduced():
    img = np.full((16, 16, 3), 0.3, np.float32)
    _, info, out = _fit(img, 50, scheme="random")
    assert np.isfinite(info.elbo).all()
    assert psnr(out, img) > 40


@pytest.mark.parametrize("shape", [(1, 1), (3, 500), (500, 3)])
def test_degenerate_image_shapes(shape):
    rng = np.random.default_rng(0)
    img = rng.uniform(size=shape + (3,)).astype(np.float32)
    post, info, out = _fit(img, 40, scheme="random")
    assert np.isfinite(out).all() and np.isfinite(info.elbo).all()
    assert np.isfinite(np.asarray(post.space.scale)).all()
    assert psnr(out, img) > psnr(np.full_like(img, img.mean()), img) - 1e-6


def test_more_components_than_pixels():
    img = load_image("astronaut", 8)
    post, info, out = _fit(img, 200)
    assert np.isfinite(out).all()
    assert psnr(out, img) > 35
    assert np.asarray(render_image(post, 8, 8)).shape == (8, 8, 3)


def test_tiny_and_huge_units():
    """The same image with positions scaled by 1e-3 and by 1e3 fits equally well."""
    img = load_image("coffee", 24)
    uv, rgb = image_to_points(img)
    scores = []
    for scale in (1e-3, 1.0, 1e3):
        prior = model.init(uv * scale, rgb, 150, key=jax.random.key(0), scheme="data")
        post, _ = fit(prior, uv * scale, rgb, iters=5)
        scores.append(psnr(np.asarray(expected_colour(post, uv * scale)).reshape(img.shape), img))
    assert np.ptp(scores) < 0.1, scores
