"""Colours fitted to the picture: known colours recovered, sums additive, lumped vs exact."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.data.scene import Frame
from vbgs.render import colour_fit
from vbgs.render.camera import from_fov
from vbgs.render.raster import rasterize
from vbgs.render.splats import Splats

BG = np.array([0.2, 0.3, 0.4], np.float32)


def two_splats(colours):
    """Two overlapping splats facing the camera at z = 2 (the near one slightly left)."""
    means = np.array([[-0.05, 0.0, 1.9], [0.05, 0.02, 2.0]], np.float32)
    covs = np.stack([np.diag([0.08, 0.06, 0.01]) ** 2, np.diag([0.07, 0.09, 0.01]) ** 2])
    return Splats(jnp.asarray(means), jnp.asarray(covs, jnp.float32),
                  jnp.asarray(colours, jnp.float32), jnp.asarray([0.8, 0.7], jnp.float32))


def views(splats, n=3):
    """``n`` frames of ``splats`` rendered over BG from cameras shifted along x."""
    frames = []
    for dx in np.linspace(-0.1, 0.1, n):
        pose = np.eye(4)
        pose[0, 3] = dx
        cam = from_fov(32, 24, np.deg2rad(40), pose)
        rgb = np.asarray(rasterize(splats, cam, background=BG).rgb)
        frames.append(Frame(rgb, np.zeros((24, 32), np.float32), cam))
    return frames


TRUE = np.array([[0.9, 0.1, 0.1], [0.1, 0.2, 0.95]], np.float32)
GREY = np.full((2, 3), 0.5, np.float32)


def test_terms_equal_the_explicit_weight_matrix():
    splats = two_splats(GREY)
    frame = views(two_splats(TRUE), 1)[0]

    def render(c):  # W c over black, linear in c: [h, w, 3]
        return rasterize(splats._replace(colours=c), frame.camera).rgb

    jac = jax.jacfwd(render)(splats.colours)  # [h, w, 3, k, 3]; forward mode, Pallas too
    w = np.asarray(jac[:, :, 0, :, 0]).reshape(-1, 2)  # [p, k] blending weights α_i T_i
    alpha = w.sum(1)  # [p]
    np.testing.assert_allclose(alpha, np.asarray(rasterize(splats, frame.camera).alpha).ravel(),
                               atol=1e-6)
    y = frame.rgb.reshape(-1, 3) - (1 - alpha)[:, None] * BG  # C - T bg
    rhs, lumped = colour_fit.frame_terms(splats, frame.camera, frame.rgb, BG)
    np.testing.assert_allclose(rhs, w.T @ y, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(lumped, w.T @ alpha, rtol=1e-4, atol=1e-5)  # row sums of WᵀW
    x = np.array([[0.3, -1.0, 2.0], [1.5, 0.5, -0.2]], np.float32)
    np.testing.assert_allclose(colour_fit.normal_matvec(splats, frame.camera, x),
                               w.T @ w @ x, rtol=1e-4, atol=1e-5)


def test_overlapping_splats_recover_their_colours():
    frames = views(two_splats(TRUE))
    splats = two_splats(GREY)  # the geometry known, the colours not
    fitted, _ = colour_fit.exact_colours(splats, frames, BG, GREY, ridge=1e-4, tol=1e-6)
    np.testing.assert_allclose(fitted, TRUE, atol=2e-3)
    # The lumped solve blends the colours of overlapping splats: not exact here.
    normal = colour_fit.no_frames(2)
    for f in frames:
        normal = colour_fit.observe(normal, splats, f.camera, f.rgb, BG)
    lumped = np.asarray(colour_fit.solve(normal, GREY, ridge=1e-4))
    assert np.abs(lumped - TRUE).max() > 0.02


def test_lumped_equals_exact_where_the_colour_is_uniform():
    uniform = np.array([[0.7, 0.6, 0.1], [0.7, 0.6, 0.1]], np.float32)
    frames = views(two_splats(uniform))
    splats = two_splats(GREY)
    exact, _ = colour_fit.exact_colours(splats, frames, BG, GREY, ridge=1e-4, tol=1e-6)
    normal = colour_fit.no_frames(2)
    for f in frames:
        normal = colour_fit.observe(normal, splats, f.camera, f.rgb, BG)
    lumped = colour_fit.solve(normal, GREY, ridge=1e-4)
    np.testing.assert_allclose(lumped, exact, atol=1e-3)
    np.testing.assert_allclose(lumped, uniform, atol=1e-3)


def test_sums_add_up_frame_by_frame_in_any_order():
    frames = views(two_splats(TRUE))
    splats = two_splats(GREY)
    forward, backward = colour_fit.no_frames(2), colour_fit.no_frames(2)
    for f in frames:
        forward = colour_fit.observe(forward, splats, f.camera, f.rgb, BG)
    for f in frames[::-1]:
        backward = colour_fit.observe(backward, splats, f.camera, f.rgb, BG)
    terms = [colour_fit.frame_terms(splats, f.camera, f.rgb, BG) for f in frames]
    np.testing.assert_allclose(forward.rhs, sum(t[0] for t in terms), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(forward.lumped, sum(t[1] for t in terms), rtol=1e-5)
    np.testing.assert_allclose(forward.rhs, backward.rhs, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(forward.lumped, backward.lumped, rtol=1e-5)


def test_unseen_components_keep_their_posterior_colour_and_bad_input_is_refused():
    normal = colour_fit.no_frames(2)
    np.testing.assert_allclose(colour_fit.solve(normal, TRUE), TRUE)
    with pytest.raises(ValueError, match="ridge must be > 0"):
        colour_fit.solve(normal, TRUE, ridge=0.0)
    frame = views(two_splats(TRUE), 1)[0]
    with pytest.raises(ValueError, match="frame rgb has shape"):
        colour_fit.frame_terms(two_splats(GREY), frame.camera, frame.rgb[:10], BG)


def test_from_posterior_takes_given_colours_clipped():
    from vbgs.inference import model
    from vbgs.render.splats import from_posterior

    rng = np.random.default_rng(0)
    xyz = rng.uniform(-1, 1, (200, 3)).astype(np.float32)  # [n, 3]
    rgb = rng.uniform(0, 1, (200, 3)).astype(np.float32)
    prior = model.init(xyz, rgb, 4, key=jax.random.PRNGKey(0), scheme="data")
    state, _ = model.update(model.start(prior), xyz, rgb)
    given = np.array([[0.2, 0.4, 0.6], [1.5, -0.1, 0.5], [0.0, 1.0, 0.3], [0.9, 0.8, 0.7]])
    out = from_posterior(state.posterior, prior, drop_unused=False, colours=given)
    np.testing.assert_allclose(out.colours, np.clip(given, 0, 1), atol=1e-7)
    default = from_posterior(state.posterior, prior, drop_unused=False)
    np.testing.assert_allclose(default.colours, np.clip(state.posterior.colour.mean, 0, 1))
