"""The tiled E-step of a frame equals the per-point sparse E-step with each point given
its tile's candidates."""

import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.inference import frame_tiles, model, projective


def _terms(k: int, rng) -> model.Terms:
    a = rng.normal(size=(k, 3, 3))
    prec = np.einsum("kij,klj->kil", a, a) + 0.5 * np.eye(3)
    return model.Terms(jnp.asarray(rng.uniform(-1, 1, (k, 3)), jnp.float32),
                       jnp.asarray(prec * 4.0, jnp.float32),
                       jnp.asarray(rng.uniform(0, 1, (k, 3)), jnp.float32),
                       jnp.asarray(rng.normal(size=k), jnp.float32))


def _frame(rng, width=22, height=13, tile=4, n_candidates=5, k=40):
    """A tiling, points at a random subset of its pixels (with padding after them) and
    each tile's candidates (some -1, one tile with none)."""
    tiling = projective.Tiling(width, height, tile, 16, n_candidates)
    n = int(0.7 * width * height)
    pixel = rng.permutation(width * height)[:n]
    pad = 8
    pixel = np.concatenate([pixel, -np.ones(pad, np.int64)]).astype(np.int32)
    x = rng.uniform(-1, 1, (n + pad, 3)).astype(np.float32)
    c = rng.uniform(0, 1, (n + pad, 3)).astype(np.float32)
    w = np.concatenate([rng.uniform(0.5, 1.5, n), np.zeros(pad)]).astype(np.float32)
    ray = (0.05 * rng.normal(size=(n + pad, 3))).astype(np.float32)
    n_tiles = tiling.tiles_x * tiling.tiles_y
    cand = rng.integers(0, k, (n_tiles, n_candidates)).astype(np.int32)
    cand[rng.uniform(size=cand.shape) < 0.2] = -1
    cand[:, 0] = rng.integers(0, k, n_tiles)  # every tile lists one, but the next
    cand[n_tiles // 2 + 1] = -1
    return tiling, pixel, x, c, w, ray, cand


@pytest.mark.parametrize("noisy", [False, True])
def test_tiled_e_step_equals_the_per_point_one(noisy):
    rng = np.random.default_rng(3)
    terms = _terms(40, rng)
    tiling, pixel, x, c, w, ray, cand = _frame(rng)
    where = frame_tiles.layout(jnp.asarray(pixel), tiling)
    padded = np.full((where.tiles, cand.shape[1]), -1, np.int32)
    padded[:len(cand)] = cand
    tile = np.asarray(where.slot) // where.per_tile
    per_point = np.vstack([padded, -np.ones((1, cand.shape[1]), np.int32)])[
        np.minimum(tile, where.tiles)]
    w[~(per_point >= 0).any(1)] = 0.0  # as the stepper leaves them: no candidate, no weight
    grid = [frame_tiles.gridded(jnp.asarray(a), where) for a in (x, c, w, ray)]
    stats, lse = frame_tiles.e_step(terms, *grid[:3], jnp.asarray(padded), 0.1,
                                    grid[3] if noisy else None)

    # the per-point step: each point its tile's candidates (padding: none listed)
    expect, expect_lse = model.e_step_with(terms, jnp.asarray(x), jnp.asarray(c),
                                           jnp.asarray(w), 0.1, len(x), jnp.asarray(per_point),
                                           jnp.asarray(ray) if noisy else None,
                                           partial_lists=True)
    for name in ("count", "sum_x", "sum_xx", "sum_c") + (("sum_noise", "sum_shift")
                                                        if noisy else ()):
        got, want = np.asarray(getattr(stats, name)), np.asarray(getattr(expect, name))
        np.testing.assert_allclose(got, want, rtol=2e-5, atol=2e-5 * np.abs(want).max(),
                                   err_msg=name)
    assert float(np.asarray(stats.count).sum()) == pytest.approx(float(w.sum()), rel=1e-5)
    listed = w > 0
    got_lse = np.asarray(frame_tiles.pointwise(lse, where))
    np.testing.assert_allclose(got_lse[listed], np.asarray(expect_lse)[listed], rtol=1e-5,
                               atol=1e-4)


def test_layout_gives_each_pixel_its_own_slot_and_round_trips():
    rng = np.random.default_rng(0)
    tiling, pixel, x, *_ = _frame(rng, width=37, height=29, tile=5)
    where = frame_tiles.layout(jnp.asarray(pixel), tiling)
    slot = np.asarray(where.slot)
    real = pixel >= 0
    assert len(np.unique(slot[real])) == real.sum()
    assert (slot[~real] == where.tiles * where.per_tile).all()
    assert where.tiles % frame_tiles.chunk(tiling.tiles_x * tiling.tiles_y) == 0
    # a pixel's slot is in the tile its projection falls in (one spare tile a side)
    row, col = pixel[real] // tiling.width, pixel[real] % tiling.width
    tile = slot[real] // where.per_tile
    assert (tile % tiling.tiles_x == col // tiling.tile + 1).all()
    assert (tile // tiling.tiles_x == row // tiling.tile + 1).all()
    back = np.asarray(frame_tiles.pointwise(frame_tiles.gridded(jnp.asarray(x), where), where))
    np.testing.assert_array_equal(back[real], x[real])
    assert (back[~real] == 0).all()


def test_tile_depths_and_nearest_distance():
    z = jnp.asarray([[1.0, 3.0, 9.0], [2.0, 2.0, 2.0]])
    w = jnp.asarray([[1.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(np.asarray(frame_tiles.tile_depths(z, w)),
                               [[1.0, 2.0, 3.0], [np.inf] * 3])
    means = jnp.asarray([[0.0, 0, 0], [1, 0, 0], [5, 5, 5]])
    x = jnp.asarray([[[0.9, 0, 0], [4, 5, 5]], [[0.0, 0, 0], [0, 0, 0]]])
    cand = jnp.asarray([[0, 1, 2], [-1, -1, -1]], jnp.int32)
    d2 = np.asarray(frame_tiles.nearest_distance(means, x, cand))
    np.testing.assert_allclose(d2[0], [0.01, 1.0], rtol=1e-5)
    assert np.isinf(d2[1]).all()


@pytest.mark.parametrize("noisy", [False, True])
def test_stepper_by_tiles_equals_the_per_point_projective_stepper(noisy, object_map):
    """A grown map's next frame learned by its tiles (the points' pixels given) and point
    by point (each point its projected tile's candidates): the same posterior, bound and
    points within reach."""
    import jax

    from vbgs.inference import grow
    from vbgs.inference.stepper import Stepper
    from vbgs.render.camera import unproject, valid_depth

    state, scene = object_map
    frame = scene.train[8]
    xyz, rgb = unproject(frame.camera, frame.rgb, frame.depth)
    pixel = np.flatnonzero(valid_depth(frame.depth))
    prior = state.mixture.prior
    ray = (0.004 * np.random.default_rng(0).normal(size=xyz.shape)).astype(np.float32) \
        if noisy else None
    reach = 0.4 * state.rule.cell  # small: some points are out of reach

    def stepper():
        return Stepper(prior, estep="sparse", search="projective", grows=True,
                       spacing=grow.mean_spacing(prior), reach=reach)

    a, ia = stepper()(model.start(prior), xyz, rgb, ray, camera=frame.camera)
    b, ib = stepper()(model.start(prior), xyz, rgb, ray, camera=frame.camera, pixel=pixel)
    np.testing.assert_array_equal(ia.learned, ib.learned)
    assert 0.2 < ib.learned.mean() < 0.99, ib.learned.mean()
    for u, w in zip(jax.tree.leaves(a.stats), jax.tree.leaves(b.stats), strict=True):
        np.testing.assert_allclose(np.asarray(w), np.asarray(u), rtol=1e-4,
                                   atol=1e-5 * float(np.abs(np.asarray(u)).max()))
    np.testing.assert_allclose(float(ib.elbo), float(ia.elbo), rtol=1e-5)


def test_stepper_refuses_pixels_that_are_not_the_points():
    import jax

    from vbgs.inference.stepper import Stepper
    from vbgs.render.camera import Camera

    rng = np.random.default_rng(0)
    cam = Camera(10.0, 10.0, 4.0, 3.0, 8, 6, np.eye(4))
    xyz = (rng.uniform(-0.3, 0.3, (5, 3)) + [0, 0, 2]).astype(np.float32)
    rgb = rng.uniform(0, 1, (5, 3)).astype(np.float32)
    prior = model.init(xyz, rgb, 4, key=jax.random.key(0), scheme="data")
    step = Stepper(prior, estep="sparse", search="projective", spacing=0.3)
    with pytest.raises(ValueError, match="flat pixel index"):
        step(model.start(prior), xyz, rgb, camera=cam, pixel=np.arange(4))
    with pytest.raises(ValueError, match="flat pixel index"):
        step(model.start(prior), xyz, rgb, camera=cam, pixel=np.array([0, 1, 2, 3, 48]))


def _left_third_wall():
    """A 48 x 32 frame of a textured wall 2 units in front of the camera and a prior of
    12 components fitted to its left third: the camera, the frame's points ``[n, 3]``
    (one a pixel, row-major), their colours, which lie on the left third ``[n]`` bool,
    and the prior."""
    import jax

    from vbgs.render.camera import from_fov, look_at, unproject

    w, h = 48, 32
    cam = from_fov(w, h, 1.2, look_at((0.0, -2.0, 0.5), (0.0, 0.0, 0.5)))
    u, v = np.meshgrid(np.linspace(0, 1, w), np.linspace(0, 1, h))
    rgb = np.stack([u, v, 0.5 * (u + v)], -1).astype(np.float32)
    xyz, col = unproject(cam, rgb, np.full((h, w), 2.0, np.float32))
    left = xyz[:, 0] < np.quantile(xyz[:, 0], 0.3)
    prior = model.init(xyz[left], col[left], 12, key=jax.random.key(1), scheme="data")
    return cam, xyz, col, left, prior


def test_points_no_tile_lists_are_learned_from_the_kdtree():
    """A wall whose components all lie on its left third: the tiles of the right two
    thirds list none of them (their pools hold only nearby tiles' components), where the
    KD-tree's nearest means lie within reach. Those points are searched again in the
    KD-tree and learned (Stepper._missed): every point learned, and what they add is
    exactly what the KD-tree stepper learns from them alone (statistics are sums under
    prior assignment)."""
    import jax

    from vbgs.inference.stepper import Stepper

    cam, xyz, col, left, prior = _left_third_wall()
    pixel = np.arange(len(xyz))  # every pixel of the wall has depth

    def step(search, pts, cols, fallback=True, **kw):
        st = Stepper(prior, estep="sparse", n_candidates=12, search=search, spacing=0.05,
                     reach=10.0)
        if not fallback:
            st._missed = lambda state, info, within, *a: (state, info, within)
        return st(model.start(prior), pts, cols, **kw)

    tiled, info = step("projective", xyz, col, camera=cam, pixel=pixel)
    alone, only = step("projective", xyz, col, False, camera=cam, pixel=pixel)
    assert info.learned.all() and only.learned.mean() < 0.5  # most were missed
    missed = ~only.learned
    kd, _ = step("kdtree", xyz[missed], col[missed])
    for a, b, c in zip(jax.tree.leaves(tiled.stats), jax.tree.leaves(alone.stats),
                       jax.tree.leaves(kd.stats), strict=True):
        np.testing.assert_allclose(np.asarray(a) - np.asarray(b), np.asarray(c),
                                   rtol=1e-4, atol=2e-3)
    assert np.isfinite(float(info.elbo))


def test_a_frame_that_misses_points_compiles_nothing_after_the_first():
    """The missed points' step is compiled with a stream's first frame: a later frame
    that misses points (here the second; the first missed none) waits for no
    compilation, and its points are learned."""
    from vbgs.inference import stepper as stepper_module

    cam, xyz, col, left, prior = _left_third_wall()
    left = np.flatnonzero(left)
    step = stepper_module.Stepper(prior, estep="sparse", n_candidates=12,
                                  search="projective", spacing=0.05, reach=10.0,
                                  max_points=len(xyz))
    state, first = step(model.start(prior), xyz[left], col[left], camera=cam, pixel=left)
    assert first.learned.all()
    compiled = stepper_module._step._cache_size(), stepper_module._with_missed._cache_size()
    _, second = step(state, xyz, col, camera=cam, pixel=np.arange(len(xyz)))
    assert second.learned.all()
    assert (stepper_module._step._cache_size(),
            stepper_module._with_missed._cache_size()) == compiled
