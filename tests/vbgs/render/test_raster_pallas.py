"""The Pallas compositing kernel (interpret mode on the CPU) held to the XLA rasterizer."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.render import raster
from vbgs.render.camera import from_fov, look_at
from vbgs.render.raster import NEAR, rasterize, resolve_impl
from vbgs.render.splats import Splats, covs_from_scale_rotation

TOL = 1e-5  # Pallas vs XLA, float32 (the two differ only in summation order)


def mixed_scene(seed, k=120, width=32, height=16):
    """k splats around a camera at the origin looking along +y: a dense overlapping cluster
    in view, some behind the camera, some grazing the near plane, some off to the side."""
    rng = np.random.default_rng(seed)
    means = rng.normal(0, 0.35, (k, 3)) + [0.0, 2.5, 0.0]  # overlapping cluster in view
    q = k // 6
    means[:q] *= [1, -1, 1]  # behind the camera
    means[q : 2 * q, 1] = rng.uniform(0.08, 0.3, q)  # around z = sqrt(tr cov) (~0.14): culled near
    means[2 * q : 3 * q, 0] += rng.choice([-3.0, 3.0], q)  # beside the view
    scales = 0.08 * np.exp(rng.normal(0, 0.5, (k, 3)))
    covs = covs_from_scale_rotation(jnp.asarray(scales), jnp.asarray(rng.normal(size=(k, 4))))
    splats = Splats(
        jnp.asarray(means, jnp.float32), jnp.asarray(covs, jnp.float32),
        jnp.asarray(rng.uniform(0, 1, (k, 3)), jnp.float32),
        jnp.asarray(rng.uniform(0.2, 0.95, k), jnp.float32),
    )
    camera = from_fov(width, height, np.deg2rad(60), look_at((0, 0, 0), (0, 1, 0)))
    return splats, camera


def max_diffs(a, b):
    return {f: float(np.abs(np.asarray(x) - np.asarray(y)).max())
            for f, x, y in zip(a._fields[:3], a[:3], b[:3], strict=True)}


@pytest.mark.parametrize("seed, tile, capacity, background", [
    (0, 8, 256, (0.0, 0.0, 0.0)),  # 8 tiles, several chunks per tile
    (1, 16, 100, (0.2, 0.5, 1.0)),  # capacity not a power of two, a partial last chunk
    (2, 8, 24, (0.3, 0.3, 0.3)),  # capacity below the chunk size: splats dropped
])
def test_pallas_equals_xla(seed, tile, capacity, background):
    splats, camera = mixed_scene(seed)
    kwargs = dict(tile=tile, capacity=capacity, background=background)
    xla = rasterize(splats, camera, impl="xla", **kwargs)
    pallas = rasterize(splats, camera, impl="pallas", **kwargs)
    counts = np.asarray(raster._tile_counts(
        splats, camera.fx, camera.fy, camera.cx, camera.cy, camera.pose, NEAR,
        width=camera.width, height=camera.height, tile=tile, blur=raster.BLUR_VARIANCE))
    assert counts.size > 1 and counts.max() > raster.DEPTH_CHUNK // 2  # several tiles, overlaps
    assert float(xla.alpha.max()) > 0.9  # the cluster is in view
    assert int(pallas.dropped) == int(xla.dropped)
    assert (int(xla.dropped) > 0) == (counts.max() > capacity)  # the last case drops splats
    diffs = max_diffs(xla, pallas)
    assert all(d < TOL for d in diffs.values()), diffs


def test_pallas_gradients_equal_xla_gradients():
    splats, camera = mixed_scene(3, k=60, width=16, height=16)
    target = jax.random.uniform(jax.random.key(0), (16, 16, 3))

    def loss(s, impl):
        out = rasterize(s, camera, tile=8, capacity=64, impl=impl)
        return jnp.sum((out.rgb - target) ** 2) + 0.1 * jnp.sum(out.depth) + jnp.sum(out.alpha)

    value_xla, grad_xla = jax.value_and_grad(loss)(splats, "xla")
    value_pallas, grad_pallas = jax.value_and_grad(loss)(splats, "pallas")
    np.testing.assert_allclose(value_pallas, value_xla, rtol=1e-6)
    for name, g_xla, g_pallas in zip(Splats._fields, grad_xla, grad_pallas, strict=True):
        g_xla = np.asarray(g_xla)
        assert np.abs(g_xla).max() > 1e-3, name  # a real gradient
        np.testing.assert_allclose(g_pallas, g_xla, rtol=1e-5, atol=1e-5 * np.abs(g_xla).max(),
                                   err_msg=name)


def test_pallas_forward_mode_equals_xla():
    """``jax.jvp`` through the kernel (a custom JVP) gives the XLA path's tangent; a custom
    VJP refused forward mode (the colour fit's tests take ``jax.jacfwd`` of a render)."""
    splats, camera = mixed_scene(4, k=40, width=16, height=16)
    direction = Splats(*(jax.random.normal(jax.random.key(i), jnp.shape(a), jnp.float32)
                         for i, a in enumerate(splats)))

    def render(s, impl):
        out = rasterize(s, camera, tile=8, capacity=64, impl=impl)
        return out.rgb, out.depth, out.alpha

    _, t_xla = jax.jvp(lambda s: render(s, "xla"), (splats,), (direction,))
    _, t_pallas = jax.jvp(lambda s: render(s, "pallas"), (splats,), (direction,))
    for a, b in zip(t_xla, t_pallas, strict=True):
        assert np.abs(np.asarray(a)).max() > 1e-3  # a real tangent
        np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-5 * np.abs(np.asarray(a)).max())


def test_float64_takes_the_xla_path():
    """The kernel computes in float32: float64 splats (``jax.enable_x64``) are composited
    by the XLA path, to the bit, and differentiate in float64."""
    with jax.enable_x64(True):
        splats, camera = mixed_scene(5, k=30, width=16, height=16)
        splats = Splats(*(jnp.asarray(a, jnp.float64) for a in splats))
        xla = rasterize(splats, camera, tile=8, capacity=64, impl="xla")
        pallas = rasterize(splats, camera, tile=8, capacity=64, impl="pallas")
        assert pallas.rgb.dtype == jnp.float64
        np.testing.assert_array_equal(pallas.rgb, xla.rgb)
        grad = jax.grad(lambda s: jnp.sum(rasterize(s, camera, tile=8, capacity=64,
                                                    impl="pallas").rgb))(splats)
        assert grad.means.dtype == jnp.float64 and np.abs(np.asarray(grad.means)).max() > 0


def test_impl_choice_and_bad_names(monkeypatch):
    monkeypatch.delenv(raster.IMPL_ENV, raising=False)
    gpu = jax.default_backend() == "gpu"
    assert resolve_impl("auto", 16) == ("pallas" if gpu else "xla", False)
    assert resolve_impl("auto", 12) == ("xla", False)  # Triton blocks need a power of two
    assert resolve_impl("pallas", 8) == ("pallas", not gpu)  # interpret mode off a GPU
    assert resolve_impl("xla", 12) == ("xla", False)
    monkeypatch.setenv(raster.IMPL_ENV, "pallas")
    assert resolve_impl("auto", 16) == ("pallas", not gpu)
    assert resolve_impl("xla", 16) == ("xla", False)  # an explicit choice wins
    splats, camera = mixed_scene(0, k=4)
    with pytest.raises(ValueError, match="impl must be one of auto, xla, pallas, got 'cuda'"):
        rasterize(splats, camera, impl="cuda")
    with pytest.raises(ValueError, match="power-of-two tile.*got 12"):
        rasterize(splats, camera, tile=12, impl="pallas")
    monkeypatch.setenv(raster.IMPL_ENV, "triton")
    with pytest.raises(ValueError, match="VBGS_RASTER_IMPL must be one of .* got 'triton'"):
        rasterize(splats, camera)


def test_kernel_lowers_to_triton():
    """Lowered for CUDA (no GPU needed), the compositing becomes one Triton kernel."""
    splats, camera = mixed_scene(0, k=20)

    def render(s):
        return raster._rasterize(s, camera.fx, camera.fy, camera.cx, camera.cy, camera.pose,
                                 jnp.zeros(3), NEAR, width=camera.width, height=camera.height,
                                 tile=16, capacity=128, blur=raster.BLUR_VARIANCE,
                                 impl="pallas", interpret=False)

    text = jax.jit(render).trace(splats).lower(lowering_platforms=("cuda",)).as_text()
    assert text.count("custom_call @__gpu$xla.gpu.triton") == 1
    assert "grid_x = 2 : i32" in text  # one program per tile (2 x 1 tiles of 16 px)
