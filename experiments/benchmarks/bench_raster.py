"""Timing of the tiled splat rasterizer (:func:`vbgs.render.raster.rasterize`).

The scene is deterministic: ``count`` splats on a bumpy sphere of radius ~1 seen
from distance ~3.6 with a 50° horizontal field of view, each with per-axis
sigma around SPLAT_SIGMA (≈ 1.3 px at 256 px, ≈ 0.7 px at 128 px), random
orientation, colour and opacity. Splats on the far side of the sphere are
rendered too (they are occluded, not culled), as in a real object scan.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.render.camera import Camera, from_fov, look_at
from vbgs.render.raster import (
    DEFAULT_CAPACITY,
    DEFAULT_TILE,
    DEPTH_CHUNK,
    rasterize,
    required_capacity,
    resolve_impl,
)
from vbgs.render.splats import Splats, covs_from_scale_rotation

SPLAT_SIGMA = 0.015  # median per-axis standard deviation, scene units
SIGMA_SPREAD = 0.4  # log-normal spread of the per-axis sigmas
BUMP_AMPLITUDE = 0.1  # radial bumps on the unit sphere
OPACITY_RANGE = (0.3, 1.0)
FOV_DEGREES = 50.0
EYE = (0.0, -3.5, 0.8)  # camera centre, looking at the origin


def benchmark_scene(count: int, size: int, *, seed: int = 0) -> tuple[Splats, Camera]:
    """``count`` splats on a bumpy unit sphere and a ``size`` x ``size`` camera looking at it."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(count, 3))  # [k, 3]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = 1.0 + BUMP_AMPLITUDE * np.sin(5 * direction[:, 0]) * np.cos(3 * direction[:, 1])
    scales = SPLAT_SIGMA * np.exp(SIGMA_SPREAD * rng.normal(size=(count, 3)))  # [k, 3]
    covs = covs_from_scale_rotation(jnp.asarray(scales), jnp.asarray(rng.normal(size=(count, 4))))
    splats = Splats(
        jnp.asarray(direction * radius[:, None], jnp.float32),
        jnp.asarray(covs, jnp.float32),
        jnp.asarray(rng.uniform(size=(count, 3)), jnp.float32),
        jnp.asarray(rng.uniform(*OPACITY_RANGE, size=count), jnp.float32),
    )
    camera = from_fov(size, size, np.deg2rad(FOV_DEGREES), look_at(EYE, (0.0, 0.0, 0.0)))
    return splats, camera


def table_name(impl: str, tile: int = DEFAULT_TILE) -> str:
    """The results file for ``impl`` on this backend: ``bench_raster`` for the XLA path on
    the CPU (the committed table), ``bench_raster_<impl>_<backend>`` otherwise, so a GPU
    or Pallas run never overwrites the CPU figures."""
    resolved, _ = resolve_impl(impl, tile)
    backend = jax.default_backend()
    return "bench_raster" if (resolved, backend) == ("xla", "cpu") else \
        f"bench_raster_{resolved}_{backend}"


def _timed(fn, *args) -> float:
    """Wall time of one call, waiting for the result."""
    start = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return time.perf_counter() - start


def bench_rasterizer(
    sizes=(128, 256),
    counts=(10_000, 50_000),
    repeats: int = 3,
    *,
    tile: int = DEFAULT_TILE,
    capacity: int | None = DEFAULT_CAPACITY,
    impl: str = "auto",
) -> list[dict]:
    """Forward and forward+backward wall times of ``rasterize`` for every size x count.

    ``capacity=None`` uses, per scene, the smallest multiple of DEPTH_CHUNK that
    drops nothing (:func:`vbgs.render.raster.required_capacity`). Each row: size, splats, tile, capacity, forward_s and forward_backward_s
    (median of ``repeats`` calls after one warm-up call), compile_s and
    compile_backward_s (the warm-up calls, i.e. tracing + XLA compile + one run),
    and dropped (splat-tile overlaps beyond ``capacity``; 0 means the render is exact).
    The backward pass is the gradient of a photometric L2 loss w.r.t. all splat arrays.
    ``impl``: the rasterizer's compositing ("auto", "xla", "pallas"; see
    :func:`vbgs.render.raster.resolve_impl`); each row names the one used (Pallas off a GPU runs
    in interpret mode, far slower: a correctness run, not a speed figure), the backend
    and the device.
    """
    resolved, interpret = resolve_impl(impl, tile)
    where = {"impl": resolved + (" (interpret)" if interpret else ""),
             "backend": jax.default_backend(), "device": jax.devices()[0].device_kind}
    rows = []
    for size in sizes:
        for count in counts:
            splats, camera = benchmark_scene(count, size)
            cap = capacity or DEPTH_CHUNK * -(-required_capacity(splats, camera, tile=tile)
                                               // DEPTH_CHUNK)
            target = jnp.full((size, size, 3), 0.5, jnp.float32)

            def render(s, camera=camera, cap=cap):
                return rasterize(s, camera, tile=tile, capacity=cap, impl=impl)

            def loss(s, render=render, target=target):
                return jnp.sum((render(s).rgb - target) ** 2)

            forward = jax.jit(render)
            forward_backward = jax.jit(jax.value_and_grad(loss))
            compile_s = _timed(forward, splats)
            compile_backward_s = _timed(forward_backward, splats)
            rows.append(
                {
                    **where,
                    "size": size,
                    "splats": count,
                    "tile": tile,
                    "capacity": cap,
                    "forward_s": float(np.median([_timed(forward, splats) for _ in range(repeats)])),
                    "forward_backward_s": float(
                        np.median([_timed(forward_backward, splats) for _ in range(repeats)])
                    ),
                    "dropped": int(forward(splats).dropped),
                    "compile_s": compile_s,
                    "compile_backward_s": compile_backward_s,
                }
            )
    return rows
