"""Stream initialisation (vbgs.inference.grow): components on arrived data only, one per empty
cell, within the budget and the rate, deterministic under the key; empty slots are inert."""

import jax
import numpy as np
import pytest

from vbgs.data.images import load_image
from vbgs.inference import cells, grow, model


def lattice(n: int, offset=(0.0, 0.0)) -> np.ndarray:
    """Pixel-like points: an n x n grid with spacing 1, ``[n*n, 2]``."""
    u, v = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    return (np.stack([u.ravel(), v.ravel()], -1) + np.asarray(offset)).astype(np.float32)


def colours(xy: np.ndarray) -> np.ndarray:
    return np.tile(np.float32([0.2, 0.5, 0.8]), (len(xy), 1))


def test_covered_area_of_a_grid_is_one_pixel_per_point():
    assert grow.covered_area(lattice(8)) == pytest.approx(64.0)
    assert grow.covered_area(2.5 * lattice(6)) == pytest.approx(36 * 6.25)


def _kd_tree_area(pts) -> float:
    from scipy.spatial import cKDTree

    pts = np.asarray(pts, np.float64)
    spacing = float(np.median(cKDTree(pts).query(pts, k=2)[0][:, 1]))
    return len(pts) * spacing**2


@pytest.mark.parametrize("h, w, scale, offset, on_lattice", [
    (64, 64, 1.0, 0.0, True), (3, 17, 1.0, 0.0, True), (1, 9, 1.0, 0.0, True),
    (5, 4, 0.25, 0.0, True), (7, 6, 2.5, -3.0, True),
    (5, 4, 0.1, 0.0, False), (6, 5, 1 / 3, 1e3, False)])  # rounded: uneven steps
def test_covered_area_of_a_lattice_is_the_kd_tree_s_to_the_bit(h, w, scale, offset,
                                                               on_lattice):
    from vbgs.render.pixels import pixel_centres

    pts = pixel_centres(h, w).astype(np.float64) * scale + offset
    assert (grow.lattice_step(pts) is not None) == on_lattice
    assert grow.covered_area(pts) == _kd_tree_area(pts)


def test_points_off_a_full_lattice_use_the_kd_tree():
    grid = lattice(6)
    for pts in (grid[1:], np.concatenate([grid[:-1], grid[:1]]),  # a hole; a hole + repeat
                grid * [1.0, 1.5], np.concatenate([grid, [[0.25, 0.5]]]),
                np.random.default_rng(0).random((50, 3))):
        if grow.lattice_step(np.asarray(pts, np.float64)) is None:
            assert grow.covered_area(pts) == _kd_tree_area(pts)
    assert grow.lattice_step(np.concatenate([grid[:-1], grid[:1]]).astype(float)) is None
    assert grow.lattice_step(grid[1:].astype(float)) is None
    assert grow.lattice_step((grid * [1.0, 1.5]).astype(float)) == 1.0  # steps 1 and 1.5
    cube = np.stack(np.meshgrid(np.arange(4) * 0.75, np.arange(3) * 1.5, np.arange(5) * 0.5,
                                indexing="ij"), -1).reshape(-1, 3)
    assert grow.lattice_step(cube) == 0.5 and grow.covered_area(cube) == _kd_tree_area(cube)


def test_one_component_per_empty_cell_on_the_batch_points():
    xy = lattice(8)  # 64 points; cells of side 2 about the centre 3.5: 4 x 4 hold points
    rule = grow.Growth(cell=2.0, levels=1, refine=0.0, max_new=100)
    state = grow.start_empty(xy, 40, rule.cell)
    assert not grow.is_active(state.prior).any()
    state, info = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(0))
    expected = len(np.unique(np.floor((xy - 3.5) / 2.0), axis=0))
    assert info.n_new == info.n_ground == info.n_active == expected == 16
    active = grow.is_active(state.prior)
    means = np.asarray(state.prior.space.mean + state.prior.origin)[active]
    # every new mean is a batch point, and no two share a cell
    assert np.isin(means.view("f4,f4"), xy.view("f4,f4")).all()
    assert len(np.unique(np.floor((means - 3.5) / 2.0), axis=0)) == 16
    np.testing.assert_allclose(np.asarray(state.prior.colour.mean)[active], colours(means))
    # the same ground again: nothing new; new ground next to it: only its own cells
    again, info = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(1))
    assert info.n_new == 0
    right = lattice(8, offset=(8.0, 0.0))
    _, info = grow.grow(again, right, colours(right), rule, key=jax.random.key(2))
    new_cells = {tuple(c) for c in np.floor((right - 3.5) / 2.0)} - {
        tuple(c) for c in np.floor((xy - 3.5) / 2.0)}
    assert info.n_new == len(new_cells)


def test_budget_rate_and_determinism():
    xy = lattice(16)
    rule = grow.Growth(cell=1.0, levels=1, refine=0.0, max_new=30)
    state = grow.start_empty(xy, 50, rule.cell)
    a, info = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(3))
    assert info.n_new == 30  # the rate
    b, _ = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(3))
    np.testing.assert_array_equal(np.asarray(a.prior.space.mean), np.asarray(b.prior.space.mean))
    c, _ = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(4))
    assert not np.array_equal(np.asarray(a.prior.space.mean), np.asarray(c.prior.space.mean))
    a, info = grow.grow(a, xy, colours(xy), rule, key=jax.random.key(5))
    assert info.n_new == 20 and info.n_active == 50  # the budget K
    _, info = grow.grow(a, xy, colours(xy), rule, key=jax.random.key(6))
    assert info.n_new == 0


def test_refinement_fills_finer_cells_within_its_share():
    xy = lattice(8)
    rule = grow.Growth(cell=4.0, levels=3, refine=0.5, max_new=100)
    state = grow.start_empty(xy, 64, rule.cell)
    state, info = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(0))
    ground = len(np.unique(np.floor((xy - 3.5) / 4.0), axis=0))  # 9 cells of side 4
    assert info.n_ground == ground
    assert info.n_new - ground == np.floor(0.5 * (64 - ground))  # refinement took its share


@pytest.mark.parametrize("estep", ["dense", "sparse"])
def test_empty_slots_take_no_responsibility(estep):
    xy = lattice(8)
    rule = grow.Growth(cell=2.0, levels=1, refine=0.0, max_new=100)
    state = grow.start_empty(xy, 60, rule.cell)
    state, info = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(0))
    state, _ = model.update(state, xy, colours(xy), assign="posterior", estep=estep)
    counts = np.asarray(state.stats.count)
    active = grow.is_active(state.prior)
    assert counts[~active].max() == 0.0
    np.testing.assert_allclose(counts[active].sum(), 64.0, rtol=1e-5)


def test_cell_keys_equal_exactly_for_equal_cells_packed_or_not():
    rng = np.random.default_rng(0)
    rows = rng.integers(-3, 4, (500, 3))
    got = cells.cell_keys(rows)
    want = np.unique(rows, axis=0, return_inverse=True)[1].reshape(-1)
    # a bijection between the keys and the rows: same cell <=> same key
    assert len(set(zip(got, want, strict=False))) == len(set(got)) == len(set(want))
    lo = rows.min(0)  # packed: np.ravel_multi_index over the box
    assert np.array_equal(got, np.ravel_multi_index(tuple((rows - lo).T),
                                                    tuple(rows.max(0) - lo + 1)))
    wide = rows.copy()
    wide[:, 0] *= 2**40  # a box too wide to pack into one int64: unique over rows
    wide[:, 1] *= 2**30
    again = cells.cell_keys(wide)
    assert len(set(zip(again, want, strict=False))) == len(set(again)) == len(set(want))


@pytest.mark.parametrize("noisy", [False, True])
def test_pick_takes_the_first_point_of_each_cell_no_component_holds(noisy):
    """_pick (packed keys, a table or a binary search) against the rule written out with a set."""
    rng = np.random.default_rng(1)
    x = rng.uniform(-2.0, 2.0, (3000, 3))
    taken = rng.uniform(-3.0, 3.0, (400, 3))
    ray = rng.normal(0.0, 0.05, (3000, 3)) if noisy else None
    order = rng.permutation(len(x))
    got = grow._pick(x, taken, 0.5, order, 10**6, ray)
    held = {tuple(c) for c in cells.cell_index(taken, 0.5)}
    shifted = [x] if ray is None else [x, x - grow.NOISE_SIGMAS * ray,
                                       x + grow.NOISE_SIGMAS * ray]
    point_cells = [cells.cell_index(s, 0.5) for s in shifted]
    want, seen = [], set()
    for i in order:
        if any(tuple(c[i]) in held for c in point_cells) or tuple(point_cells[0][i]) in seen:
            continue
        seen.add(tuple(point_cells[0][i]))
        want.append(i)
    assert 50 < len(want) < len(x) and np.array_equal(got, want)
    assert np.array_equal(grow._pick(x, taken, 0.5, order, 7, ray), want[:7])


def test_batch_prior_is_growth_from_the_empty_state_to_the_bit():
    """batch_prior skips the state (its start and M-step): the same prior as growing the
    empty state by the whole batch."""
    img = load_image("coffee", 16)
    from vbgs.data.images import image_to_points

    uv, rgb = image_to_points(img)
    key = jax.random.key(3)
    rule = grow.calibrate(uv, 100, 100, rate=1.0, refine=1.0)
    state, _ = grow.grow(grow.start_empty(uv, 100, rule.cell), uv, rgb, rule, key=key)
    fast = grow.batch_prior(uv, rgb, 100, key=key)
    for a, b in zip(jax.tree.leaves(fast), jax.tree.leaves(state.prior), strict=True):
        assert a.dtype == b.dtype and np.asarray(a).tobytes() == np.asarray(b).tobytes()


def _tilted_plane(n: int = 400, seed: int = 0):
    """Points on the plane through (1, 2, 3) with unit normal ``normal``, ``[n, 3]``."""
    rng = np.random.default_rng(seed)
    normal = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    a = np.cross(normal, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    uv = rng.uniform(-1, 1, (n, 2))
    return np.array([1.0, 2.0, 3.0]) + uv[:, :1] * a + uv[:, 1:] * b, normal


def test_local_normals_of_a_plane_and_a_sphere():
    pts, normal = _tilted_plane()
    got = grow.local_normals(pts, np.arange(0, 400, 37))
    np.testing.assert_allclose(np.abs(got @ normal), 1.0, atol=1e-6)  # sign is free
    rng = np.random.default_rng(1)
    sphere = rng.normal(size=(4000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    got = grow.local_normals(sphere, np.arange(10))
    assert np.abs(np.sum(got * sphere[:10], 1)).min() > 0.99  # radial


def test_surface_scales_flatten_along_the_normal_only():
    n = np.array([[0.0, 0.6, 0.8]])
    out = grow.surface_scales(4.0, n, 0.1)[0]
    np.testing.assert_allclose(out @ n[0], 4.0 * 0.1**2 * n[0], atol=1e-12)
    t = np.array([1.0, 0.0, 0.0])  # in the plane: untouched
    np.testing.assert_allclose(out @ t, 4.0 * t, atol=1e-12)
    np.testing.assert_allclose(grow.surface_scales(4.0, n, 1.0)[0], 4.0 * np.eye(3))


def test_components_grown_on_a_surface_get_a_prior_flat_along_it():
    pts, normal = _tilted_plane(900)
    rgb = np.full((len(pts), 3), 0.5, np.float32)
    pts = pts.astype(np.float32)
    rule = grow.calibrate(pts, 100, 50)
    for thickness in (0.1, 1.0):
        config = model.PriorConfig(surface_thickness=thickness)
        state = grow.start_empty(pts, 100, rule.cell, config)
        state, info = grow.grow(state, pts, rgb, rule, key=jax.random.key(0), config=config)
        assert info.n_new > 20
        scale = np.asarray(state.prior.space.scale, np.float64)[info.slots]
        free = scale[0, 0, 0] if thickness == 1.0 else None
        along = np.einsum("i,mij,j->m", normal, scale, normal)
        within = np.linalg.eigvalsh(scale)[:, -1]
        if thickness == 1.0:  # isotropic: every slot keeps its empty prior
            np.testing.assert_allclose(scale, np.broadcast_to(free * np.eye(3), scale.shape),
                                       rtol=1e-6)
        else:
            np.testing.assert_allclose(along / within, thickness**2, rtol=0.05)
        # the fitted posterior of a flat prior is flat too: thin along the normal
        post = np.asarray(state.posterior.space.scale, np.float64)[info.slots]
        assert np.all(np.einsum("i,mij,j->m", normal, post, normal) <= within * 1.0001)


def test_two_d_models_ignore_the_surface_thickness():
    xy = lattice(12)
    config = model.PriorConfig(surface_thickness=0.1)
    rule = grow.calibrate(xy, 40, 40)
    state = grow.start_empty(xy, 40, rule.cell, config)
    state, info = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(0), config=config)
    scale = np.asarray(state.prior.space.scale)[info.slots]
    np.testing.assert_allclose(scale, np.broadcast_to(scale[0, 0, 0] * np.eye(2), scale.shape))


def test_far_ground_is_new_only_in_its_coarse_cell():
    """A point seen coarse_from (4) times or more coarsely than the first batch's median
    is new ground only where its coarse cell (side cell * 2^j) holds no component."""
    rule = grow.Growth(cell=1.0, levels=1, refine=0.0, max_new=100, coarse=3,
                       footprint=0.01, coarse_from=4.0)
    levels = grow.point_levels(rule, np.array([0.005, 0.02, 0.039, 0.04, 0.08, 0.17, 9.0]))
    assert levels.tolist() == [0, 0, 0, 1, 2, 3, 3]  # capped at rule.coarse
    assert grow.point_levels(rule._replace(coarse=0), np.ones(3)) is None
    # two far points 4 apart, a component 1.5 from the first: level 0 (cells of 1) sees
    # both as new ground, level 2 (cells of 4) only the second's cell is empty
    x = np.array([[0.5, 0.5, 0.5], [4.5, 0.5, 0.5]])
    taken = np.array([[2.0, 0.5, 0.5]])
    order = np.arange(2)
    assert len(grow.new_ground(x, taken, rule, order, 10)) == 2
    far = grow.new_ground(x, taken, rule, order, 10, levels=np.array([2, 2]))
    assert far.tolist() == [1]


def test_calibrate_with_coarse_ground_gives_the_first_batch_its_share():
    """With far points on coarse cells the first batch gets first_cells components on
    new ground (the cell side counted by bisection), not area / cell^2 of them; without
    any, the side is the area's."""
    rng = np.random.default_rng(0)
    near = np.c_[rng.uniform(0, 1, (4000, 2)), np.zeros(4000)]
    far = np.c_[rng.uniform(0, 20, (2000, 2)), np.full(2000, 5.0)]
    xyz = np.concatenate([near, far])
    footprint = np.r_[np.full(4000, 0.016), np.full(2000, 0.45)]  # as the points lie
    rule = grow.calibrate(xyz, 5000, 2000, footprint=footprint, coarse=5)
    levels = grow.point_levels(rule, footprint)
    assert levels[:4000].max() == 0 and levels[4000:].min() == 3  # 28x: 1 + floor(log2(7))
    x = xyz - 0.5 * (xyz.min(0) + xyz.max(0))
    n = len(grow.new_ground(x, np.zeros((0, 3)), rule, np.arange(len(x)), len(x), None, levels))
    assert abs(n - 2000) <= 40  # the count moves in steps
    flat = grow.calibrate(near, 5000, 500, footprint=np.full(4000, 0.016), coarse=5)
    assert flat.cell == grow.calibrate(near, 5000, 500).cell


def test_shortfall_counts_only_when_the_empty_slots_may_not_suffice():
    """While the empty slots alone take a batch's most (rule.max_new) the shortfall is a
    bound <= 0, not counted; below that it is the count: new ground less the empty slots."""
    pts = lattice(16)  # 16 cells of 4 x 4 points
    rule = grow.calibrate(pts, 20, 16, rate=0.5)  # at most 10 new a batch
    state = grow.start_empty(pts, 20, rule.cell)
    assert grow.shortfall(state, pts, rule) == rule.max_new - 20 < 0  # a bound
    for n, key in ((128, 0), (192, 1)):  # 8 cells, then 4 more
        state, _ = grow.grow(state, pts[:n], colours(pts[:n]), rule, key=jax.random.key(key))
    empty = int((~grow.is_active(state.prior)).sum())
    assert empty == 8 < rule.max_new  # now counted: 4 cells of new ground left
    assert grow.shortfall(state, pts, rule) == 4 - empty


def test_empty_prior_is_kept_and_equal_to_a_fresh_one():
    origin = np.float32([0.5, -1.0, 2.0])
    first = grow.empty_prior(32, origin, 0.1)
    assert grow.empty_prior(32, origin.copy(), 0.1) is first  # kept
    fresh = grow._empty_prior(32, origin, 0.1, model.PriorConfig(), np.dtype(np.float32))
    for a, b in zip(jax.tree.leaves(first), jax.tree.leaves(fresh), strict=True):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()
    other = grow.empty_prior(32, origin + 1, 0.1)
    assert other is not first and not np.array_equal(other.origin, first.origin)


def test_a_small_quota_picks_from_a_prefix_the_cells_a_full_pass_picks():
    """_pick reads only a prefix of the order when its quota is far under the points; the
    cells it returns are those a pass over every point returns, with noise along rays or
    without, whether the prefix holds enough empty cells or not."""
    from vbgs.inference.grow import PREFIX_TIMES, _first_cells, _pick

    rng = np.random.default_rng(3)
    x = rng.uniform(-1, 1, (40000, 3)) * [1.0, 1.0, 0.02]  # a noisy slab
    taken = rng.uniform(-1, 1, (3000, 3)) * [1.0, 1.0, 0.02]
    ray = np.tile([0.0, 0.0, 0.004], (len(x), 1))
    order = rng.permutation(len(x))
    checked_prefix = False
    for cell in (0.05, 0.2, 1.5):  # many empty cells, some, none beyond the taken ones
        for quota in (1, 7, 60, 150, 600, 2400):
            for r in (None, ray):
                full = _first_cells(x, taken, cell, order, quota, r)
                np.testing.assert_array_equal(_pick(x, taken, cell, order, quota, r), full)
                checked_prefix |= 2 * PREFIX_TIMES * quota <= len(x) and len(full) == quota
    assert checked_prefix


def test_cells_of_held_positions_are_not_new_ground():
    """``held``: positions about the grid's origin whose cells count as held though no
    component's mean lies there (a component's seed after its mean moved away). The
    cells holding them get nothing; the shortfall does not count them either."""
    xy = lattice(8)  # 16 cells of side 2 about the centre 3.5
    rule = grow.Growth(cell=2.0, levels=1, refine=0.0, max_new=100)
    state = grow.start_empty(xy, 40, rule.cell)
    held = np.float64([[-3.0, -3.0], [3.0, 3.0]])  # about the origin: two corner cells
    _, info = grow.grow(state, xy, colours(xy), rule, key=jax.random.key(0), held=held)
    assert info.n_new == 16 - 2
    full = grow.Growth(cell=2.0, levels=1, refine=0.0, max_new=10)  # 10 new at most
    state = grow.start_empty(xy, 12, full.cell)
    state, _ = grow.grow(state, xy[:32], colours(xy[:32]), full, key=jax.random.key(1))
    assert grow.shortfall(state, xy, full) > grow.shortfall(state, xy, full, held=held)


@pytest.mark.parametrize("noisy", [False, True])
@pytest.mark.parametrize("leveled", [False, True])
def test_new_ground_found_once_is_picked_as_a_pass_picks_it(noisy, leveled):
    """The ground found once (grow.ground) gives new_ground's answer in any order and at
    any quota (points of four coarse levels, noise along rays or none, quotas that stop
    within a level and that take every cell), and its count is what new_ground takes
    with a quota of every point: what shortfall counts and growth then picks."""
    rng = np.random.default_rng(4)
    x = rng.uniform(-4, 4, (30000, 3)) * [1.0, 1.0, 0.05]
    taken = rng.uniform(-4, 4, (400, 3)) * [1.0, 1.0, 0.05]
    ray = np.tile([0.0, 0.0, 0.01], (len(x), 1)) if noisy else None
    # farther ground coarser, as a frame's footprints grow with depth; a few points of
    # each level among the next level's
    levels = np.minimum(np.abs(x[:, 0]).astype(np.int64), 3)
    levels = np.where(rng.random(len(x)) < 0.02, np.maximum(levels - 1, 0), levels)
    levels = levels if leveled else None
    rule = grow.Growth(cell=0.25, levels=1, refine=0.0, max_new=10**6)
    found = grow.ground(x, taken, rule, ray, levels)
    every = grow.new_ground(x, taken, rule, np.arange(len(x)), len(x), ray, levels)
    assert found.n_cells == len(every) > 100
    stops_within_a_level = False
    for seed, quota in ((0, 5), (1, 97), (2, len(every) - 10), (3, len(every) + 1)):
        order = np.random.default_rng(seed).permutation(len(x))
        want = grow.new_ground(x, taken, rule, order, quota, ray, levels)
        got = grow.new_ground(x, taken, rule, order, quota, ray, levels, found)
        np.testing.assert_array_equal(got, want)
        if levels is not None:
            stops_within_a_level |= 0 < quota < len(every) and len(np.unique(levels[want])) > 1
    assert stops_within_a_level or levels is None


def test_shortfall_and_growth_from_the_ground_found_once_are_those_found_apart():
    """A map short of slots: the shortfall counted from grow.ground_of is the one counted
    alone, and growth picking from it grows the same components to the bit."""
    pts = lattice(16)
    rule = grow.calibrate(pts, 20, 16, rate=0.5)
    state = grow.start_empty(pts, 20, rule.cell)
    for n, key in ((128, 0), (192, 1)):
        state, _ = grow.grow(state, pts[:n], colours(pts[:n]), rule, key=jax.random.key(key))
    assert grow.short_of_slots(state, rule)
    found = grow.ground_of(state, pts, rule)
    assert grow.shortfall(state, pts, rule, found=found) == grow.shortfall(state, pts, rule)
    a, info_a = grow.grow(state, pts, colours(pts), rule, key=jax.random.key(2))
    b, info_b = grow.grow(state, pts, colours(pts), rule, key=jax.random.key(2), found=found)
    assert info_a.n_new == info_b.n_new > 0 and np.array_equal(info_a.slots, info_b.slots)
    for x, y in zip(jax.tree.leaves(a.prior), jax.tree.leaves(b.prior), strict=True):
        assert np.asarray(x).tobytes() == np.asarray(y).tobytes()
