"""The tiled rasterizer against the slow reference, analytic cases and finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.render import raster
from vbgs.render.camera import Camera, from_fov, look_at
from vbgs.render.raster import (
    ALPHA_MIN,
    BLUR_VARIANCE,
    FRUSTUM_CLAMP,
    NEAR,
    check_dropped,
    rasterize,
    required_capacity,
)
from vbgs.render.raster_reference import render_reference
from vbgs.render.splats import Splats, covs_from_scale_rotation

TOL = 1e-4  # fast vs reference, float32


def random_scene(seed, k, width=40, height=24, sigma=0.08, behind=0):
    """k splats in a unit ball seen from distance 3, plus `behind` splats behind the camera."""
    rng = np.random.default_rng(seed)
    means = rng.uniform(-1, 1, (k, 3)) * np.array([1.2, 0.8, 0.8])
    eye = np.array([0.0, -3.0, 0.0])
    if behind:
        means[:behind] = eye + rng.uniform(-0.5, 0.5, (behind, 3)) - [0, 1.0, 0]
    scales = sigma * np.exp(rng.normal(0, 0.4, (k, 3)))
    covs = covs_from_scale_rotation(jnp.asarray(scales), jnp.asarray(rng.normal(size=(k, 4))))
    splats = Splats(
        jnp.asarray(means, jnp.float32), jnp.asarray(covs, jnp.float32),
        jnp.asarray(rng.uniform(0, 1, (k, 3)), jnp.float32),
        jnp.asarray(rng.uniform(0.1, 0.9, k), jnp.float32),
    )
    return splats, from_fov(width, height, np.deg2rad(50), look_at(eye, (0, 0, 0)))


def max_diff(a, b):
    return {f: float(np.max(np.abs(np.asarray(x) - np.asarray(y)))) for f, x, y in
            zip(a._fields[:3], a[:3], b[:3], strict=True)}


@pytest.mark.parametrize("seed, tile, background", [(0, 8, (0, 0, 0)), (1, 16, (0.2, 0.5, 1.0))])
def test_tiled_equals_reference(seed, tile, background):
    splats, cam = random_scene(seed, 120, behind=5)
    fast = rasterize(splats, cam, tile=tile, capacity=256, background=background)
    ref = render_reference(splats, cam, background=background)
    assert int(fast.dropped) == 0
    assert float(fast.alpha.max()) > 0.5  # the scene is really in view
    diffs = max_diff(fast, ref)
    assert all(d < TOL for d in diffs.values()), diffs


def around_the_camera(seed, k=160, width=40, height=32):
    """Splats all around a camera at the origin looking along +y (a room seen from inside):
    beside and behind it, grazing the near plane, just outside the view (between the clamp
    and the cull band) and far outside it, some strongly anisotropic, some off-centre."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(k, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    distance = rng.uniform(0.15, 3.0, k)
    distance[: k // 8] = rng.uniform(NEAR * 0.9, NEAR * 1.5, k // 8)  # around the near plane
    means = direction * distance[:, None]
    scales = 0.06 * np.exp(rng.normal(0, 0.5, (k, 3)))
    scales[: k // 4, 0] *= 8.0  # needles and sheets
    covs = covs_from_scale_rotation(jnp.asarray(scales), jnp.asarray(rng.normal(size=(k, 4))))
    splats = Splats(
        jnp.asarray(means, jnp.float32), jnp.asarray(covs, jnp.float32),
        jnp.asarray(rng.uniform(0, 1, (k, 3)), jnp.float32),
        jnp.asarray(rng.uniform(0.2, 0.95, k), jnp.float32),
    )
    cam = from_fov(width, height, np.deg2rad(75), look_at((0, 0, 0), (0, 1, 0)))
    return splats, cam._replace(cx=0.4 * width)  # off-centre principal point


@pytest.mark.parametrize("seed", [0, 1])
def test_tiled_equals_independent_reference_around_the_camera(seed):
    splats, cam = around_the_camera(seed)
    w2c = np.asarray(cam.world_to_camera)
    t = np.asarray(splats.means) @ w2c[:3, :3].T + w2c[:3, 3]
    tangent_x = t[:, 0] / np.where(t[:, 2] > 0, t[:, 2], np.inf)
    hi_x = (cam.width - cam.cx) / cam.fx
    # The cases are really there: behind, near the near plane, and where the clamp binds.
    assert np.sum(t[:, 2] < 0) > 20 and np.sum(np.abs(t[:, 2] - NEAR) < 0.05) > 3
    assert np.sum((tangent_x > FRUSTUM_CLAMP * hi_x) & (t[:, 2] > NEAR)) > 3
    fast = rasterize(splats, cam, tile=8, capacity=256, background=(0.3, 0.6, 0.9))
    ref = render_reference(splats, cam, background=(0.3, 0.6, 0.9))
    assert int(fast.dropped) == 0 and float(fast.alpha.max()) > 0.5
    diffs = max_diff(fast, ref)
    assert all(d < TOL for d in diffs.values()), diffs


def test_splat_beside_the_camera_stays_small():
    """A small splat just outside the view, level with the camera: with the Jacobian
    evaluated at its true x/z it would smear across the image; clamped, it cannot."""
    cam = from_fov(32, 32, np.deg2rad(60), np.eye(4))
    hi = (cam.width - cam.cx) / cam.fx
    for tangent in (1.5 * hi, 1.9 * hi):  # between the clamp and the cull band
        z = 0.5
        splat = Splats(jnp.asarray([[tangent * z, 0.0, z]], jnp.float32),
                       jnp.asarray([0.05**2 * np.eye(3)], jnp.float32),
                       jnp.ones((1, 3)), jnp.asarray([0.9]))
        out = rasterize(splat, cam, tile=8)
        assert float(out.alpha[:, : cam.width // 2].max()) == 0.0, tangent
        np.testing.assert_allclose(out.alpha, render_reference(splat, cam).alpha, atol=1e-5)
    far_off = Splats(jnp.asarray([[30.0, 0.0, 1.0]]), jnp.asarray([0.1 * np.eye(3)]),
                     jnp.ones((1, 3)), jnp.asarray([0.9]))
    assert float(rasterize(far_off, cam, tile=8).alpha.max()) == 0.0  # culled


def test_dropped_counts_and_keeps_nearest():
    # 10 splats stacked on the optical axis, all overlapping the single 16x16 tile.
    k, capacity = 10, 4
    cam = from_fov(16, 16, np.deg2rad(40), np.eye(4))
    means = np.stack([np.zeros(k), np.zeros(k), np.linspace(3.0, 2.0, k)], -1)  # far to near
    splats = Splats(
        jnp.asarray(means, jnp.float32), jnp.tile(0.01 * jnp.eye(3), (k, 1, 1)),
        jnp.asarray(np.random.default_rng(0).uniform(size=(k, 3)), jnp.float32),
        jnp.full((k,), 0.3),
    )
    out = rasterize(splats, cam, capacity=capacity)
    assert int(out.dropped) == k - capacity
    with pytest.raises(RuntimeError, match="6 splat-tile overlaps were dropped"):
        check_dropped(out)
    assert required_capacity(splats, cam) == k
    # What was rendered is exactly the `capacity` nearest: the farthest have opacity 0.
    nearest = splats._replace(opacities=splats.opacities.at[: k - capacity].set(0.0))
    diffs = max_diff(out, render_reference(nearest, cam))
    assert all(d < TOL for d in diffs.values()), diffs


def test_isotropic_splat_head_on_is_the_analytic_gaussian():
    width, height, z, sigma, opacity = 32, 24, 2.0, 0.05, 0.8
    colour = np.array([0.9, 0.5, 0.1])
    cam = from_fov(width, height, np.deg2rad(60), np.eye(4))
    splats = Splats(
        jnp.asarray([[0.0, 0.0, z]]), jnp.asarray([sigma**2 * np.eye(3)], jnp.float32),
        jnp.asarray([colour], jnp.float32), jnp.asarray([opacity], jnp.float32),
    )
    out = rasterize(splats, cam, tile=8)
    var_px = (cam.fx * sigma / z) ** 2 + BLUR_VARIANCE  # J Σ Jᵀ + dilation, J = f/z I on axis
    v, u = np.mgrid[0:height, 0:width] + 0.5
    alpha = opacity * np.exp(-0.5 * ((u - cam.cx) ** 2 + (v - cam.cy) ** 2) / var_px)
    alpha = np.where(alpha >= ALPHA_MIN, alpha, 0.0)
    np.testing.assert_allclose(out.alpha, alpha, atol=1e-6)
    np.testing.assert_allclose(out.rgb, alpha[..., None] * colour, atol=1e-6)
    np.testing.assert_allclose(out.depth, alpha * z, atol=1e-5)
    assert 0 < np.sum(alpha == 0) < alpha.size  # the cut-off is inside the image


def test_splats_behind_the_camera_do_not_render():
    splats, cam = random_scene(0, 120, behind=5)  # same shapes as the first test: no recompile
    w2c = np.asarray(cam.world_to_camera)
    cam_z = (np.asarray(splats.means) @ w2c[:3, :3].T + w2c[:3, 3])[:, 2]
    assert np.all(cam_z[:5] < 0) and np.all(cam_z[5:] > 1)
    out = rasterize(splats, cam, tile=8, capacity=256)
    without = rasterize(splats._replace(opacities=splats.opacities.at[:5].set(0.0)), cam,
                        tile=8, capacity=256)
    diffs = max_diff(out, without)
    assert all(d == 0.0 for d in diffs.values()), diffs
    # All of them behind, and blown up so their footprint would cover the image.
    behind = splats._replace(means=splats.means - 4.0 * jnp.asarray(cam.pose[:3, 2], jnp.float32),
                             covs=splats.covs * 50)
    out = rasterize(behind, cam, tile=8, capacity=256, background=(0.1, 0.2, 0.3))
    assert float(jnp.max(out.alpha)) == 0.0 and float(jnp.max(out.depth)) == 0.0
    np.testing.assert_allclose(out.rgb, np.broadcast_to([0.1, 0.2, 0.3], out.rgb.shape))


def test_an_indefinite_covariance_is_not_drawn():
    """A float32 posterior covariance can come out indefinite; its projection is no
    ellipse, so ``project`` marks it invisible and the picture is the one without it."""
    splats, cam = random_scene(0, 120)  # same shapes as the first test: no recompile
    bad = jnp.diag(jnp.array([-0.04, 0.05, 0.05], jnp.float32))  # indefinite across the view
    broken = splats._replace(covs=splats.covs.at[:3].set(bad))
    proj = raster.project(broken, cam.fx, cam.fy, cam.cx, cam.cy, jnp.asarray(cam.pose),
                          width=cam.width,
                          height=cam.height)
    assert not np.any(np.asarray(proj.visible[:3]))
    out = rasterize(broken, cam, tile=8, capacity=256)
    without = rasterize(broken._replace(opacities=broken.opacities.at[:3].set(0.0)), cam,
                        tile=8, capacity=256)
    assert np.all(np.isfinite(np.asarray(out.rgb)))
    diffs = max_diff(out, without)
    assert all(d == 0.0 for d in diffs.values()), diffs


def test_gradients_match_central_differences():
    eps, rtol = 1e-6, 1e-5
    with jax.enable_x64(True):
        splats, cam = random_scene(3, 12, width=16, height=16, sigma=0.25)
        splats = Splats(*(jnp.asarray(a, jnp.float64) for a in splats))
        rng = np.random.default_rng(4)
        w_rgb, w_depth, w_alpha = (jnp.asarray(rng.normal(size=s)) for s in
                                   ((16, 16, 3), (16, 16), (16, 16)))

        def loss(s):
            out = rasterize(s, cam, tile=8, capacity=64)
            return (jnp.sum(out.rgb * w_rgb) + jnp.sum(out.depth * w_depth)
                    + jnp.sum(out.alpha * w_alpha))

        value_and_grad = jax.jit(jax.value_and_grad(loss))  # one compile for both uses
        grads = value_and_grad(splats)[1]

        def loss_jit(s):
            return value_and_grad(s)[0]

        for field in ("means", "covs", "colours", "opacities"):
            x = np.asarray(getattr(splats, field))
            for flat in rng.choice(x.size, size=6, replace=False):
                idx = np.unravel_index(flat, x.shape)
                step = np.zeros_like(x)
                step[idx] = eps
                if field == "covs":  # perturb symmetrically, compare with the symmetric part
                    step[idx[0], idx[2], idx[1]] = eps
                fd = (loss_jit(splats._replace(**{field: x + step}))
                      - loss_jit(splats._replace(**{field: x - step}))) / (2 * eps)
                g = np.asarray(getattr(grads, field))
                analytic = g[idx] if field != "covs" or idx[1] == idx[2] else (
                    g[idx] + g[idx[0], idx[2], idx[1]])
                assert abs(float(fd) - analytic) <= rtol * max(1.0, abs(float(fd))), (
                    field, idx, float(fd), analytic)
            assert np.any(np.abs(np.asarray(getattr(grads, field))) > 1e-3), field


def test_jit_compiles_once_for_repeated_shapes():
    splats, cam = random_scene(7, 120)
    first = rasterize(splats, cam, tile=8, capacity=256)
    compiled = raster._rasterize._cache_size()
    moved = Camera(*cam[:6], look_at((0.3, -3.0, 0.2), (0, 0, 0)))
    second = rasterize(splats._replace(colours=1 - splats.colours), moved, tile=8, capacity=256,
                       background=(1, 1, 1))
    assert raster._rasterize._cache_size() == compiled
    assert int(check_dropped(second).dropped) == 0
    assert not np.allclose(first.rgb, second.rgb)
    jitted = jax.jit(lambda s: rasterize(s, cam, tile=8, capacity=256).rgb)  # under an outer jit
    np.testing.assert_allclose(jitted(splats), first.rgb, atol=1e-6)


def test_bad_input_is_reported():
    splats, cam = random_scene(6, 10)
    with pytest.raises(ValueError, match="NaN"):
        rasterize(splats._replace(means=splats.means.at[0, 0].set(jnp.nan)), cam)
    with pytest.raises(ValueError, match="malformed Splats"):
        rasterize(splats._replace(covs=splats.covs[:, :2]), cam)
    with pytest.raises(ValueError, match="opacities must lie in"):
        rasterize(splats._replace(opacities=splats.opacities + 1), cam)
    with pytest.raises(ValueError, match="background"):
        rasterize(splats, cam, background=(0, 0))
    empty = rasterize(Splats(*(a[:0] for a in splats)), cam, background=0.5)
    assert empty.rgb.shape == (cam.height, cam.width, 3) and float(empty.rgb.min()) == 0.5


def test_exact_capacity_drops_nothing_and_buckets():
    k = 10
    cam = from_fov(16, 16, np.deg2rad(40), np.eye(4))
    means = np.stack([np.zeros(k), np.zeros(k), np.linspace(3.0, 2.0, k)], -1)
    splats = Splats(jnp.asarray(means, jnp.float32), jnp.tile(0.01 * jnp.eye(3), (k, 1, 1)),
                    jnp.full((k, 3), 0.5), jnp.full((k,), 0.3))
    assert raster.exact_capacity(splats, cam) == raster.DEFAULT_CAPACITY  # 10 needed
    many = Splats(*(jnp.concatenate([a] * 300) for a in splats))  # 3000 overlaps in one tile
    capacity = raster.exact_capacity(many, cam)
    assert capacity == 4096 and int(rasterize(many, cam, capacity=capacity).dropped) == 0
