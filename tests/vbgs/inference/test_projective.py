"""vbgs.inference.projective: candidates by projection, held to the KD-tree reference."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs import mapping
from vbgs.inference import candidates, grow, model, projective
from vbgs.inference.stepper import Stepper
from vbgs.render.camera import unproject

C = 16


@pytest.fixture(scope="module")
def scene(object_map):
    return object_map[1]


@pytest.fixture(scope="module")
def grown(object_map):
    """A map grown on eight frames, and the next frame's points, centred."""
    state, scene = object_map
    frame = scene.train[8]
    xyz, rgb = unproject(frame.camera, frame.rgb, frame.depth)
    prior = state.mixture.prior
    return state, frame, (xyz - np.asarray(prior.origin)).astype(np.float32), rgb


def _search(state, frame, x, n_candidates=C, shortlist=0):
    prior = state.mixture.prior
    rot_t, shift = projective.world_to_camera(frame.camera, prior.origin)
    depth = float(np.median(x @ rot_t[2] + shift[2]))
    tiling = projective.plan(frame.camera, state.rule.cell, depth, n_candidates)
    tiling = tiling._replace(shortlist=shortlist or tiling.shortlist)
    v = projective.view(frame.camera, prior.origin)
    cand, d2 = projective.search(prior.space.mean, prior.alpha > grow.ACTIVE_ALPHA, v,
                                 jnp.asarray(x),
                                 jnp.ones(len(x), jnp.float32), tiling)
    return np.asarray(cand), np.asarray(d2)


def test_projection_finds_the_kdtree_nearest_components(grown):
    """Each point's nearest component (the one that takes most of its responsibility) is
    among its projective candidates for nearly every point, and the distance to the
    nearest candidate is the KD-tree's wherever it found that component."""
    state, frame, x, _ = grown
    prior = state.mixture.prior
    cand, d2 = _search(state, frame, x)
    dist, kd = candidates.query_with_distance(candidates.means_tree(prior.space.mean), x, C)
    found = np.array([a[0] in set(b) for a, b in zip(kd, cand, strict=True)])
    assert found.mean() > 0.97
    np.testing.assert_allclose(np.sqrt(d2[found]), dist[found], rtol=1e-4, atol=1e-6)
    active = grow.is_active(prior)
    assert active[cand[cand >= 0]].all()  # empty slots are never candidates


def test_same_components_give_the_same_responsibilities(grown):
    """Where the two searches list the same components for a point, the E-step's
    responsibilities (and log-normaliser) are the same, whatever order they are listed in."""
    state, frame, x, rgb = grown
    prior = state.mixture.prior
    cand, _ = _search(state, frame, x, n_candidates=4, shortlist=8)
    _, kd = candidates.query_with_distance(candidates.means_tree(prior.space.mean), x, 4)
    same = np.array([set(a) == set(b) for a, b in zip(kd, cand, strict=True)])
    assert same.mean() > 0.5
    terms = model.component_terms(prior, 0.1)
    xs, cs = jnp.asarray(x[same]), jnp.asarray(rgb[same])
    lp = candidates.candidate_logits(xs, cs, terms, jnp.asarray(cand[same]), 0.1)
    lk = candidates.candidate_logits(xs, cs, terms, jnp.asarray(kd[same]), 0.1)
    order_p, order_k = np.argsort(cand[same], 1), np.argsort(kd[same], 1)
    rp = np.take_along_axis(np.asarray(jax.nn.softmax(lp, -1)), order_p, 1)
    rk = np.take_along_axis(np.asarray(jax.nn.softmax(lk, -1)), order_k, 1)
    np.testing.assert_allclose(rp, rk, atol=1e-6)


def _few_components():
    """Nine components on a wall 2 units in front of an identity camera, and its pixels."""
    from vbgs.render.camera import Camera

    cam = Camera(40.0, 40.0, 16.0, 16.0, 32, 32, np.eye(4))
    g = np.linspace(-0.6, 0.6, 3)
    means = np.array([(a, b, 2.0) for a in g for b in g], np.float32)
    rng = np.random.default_rng(0)
    xyz = np.concatenate([means + rng.normal(0, 0.05, means.shape) for _ in range(30)])
    rgb = rng.uniform(0, 1, (len(xyz), 3)).astype(np.float32)
    prior = model.init(means, rng.uniform(0, 1, (9, 3)).astype(np.float32), 9,
                       key=jax.random.key(0), scheme="data")
    return cam, prior, xyz.astype(np.float32), rgb


def test_stepper_with_projection_equals_the_kdtree_stepper_when_all_are_listed():
    """Nine components, all within every point's neighbourhood: both searches list them
    all, so the learned posteriors are the same (the fast path against its reference)."""
    cam, prior, xyz, rgb = _few_components()
    spacing = grow.mean_spacing(prior)
    kd = Stepper(prior, estep="sparse", n_candidates=C, search="kdtree")
    pj = Stepper(prior, estep="sparse", n_candidates=C, search="projective", spacing=spacing)
    pj.tiling = projective.Tiling(32, 32, 16, 16, C)  # 2 x 2 tiles: every pool holds all
    a, ia = kd(model.start(prior), xyz, rgb)
    b, ib = pj(model.start(prior), xyz, rgb, camera=cam)
    for u, w in zip(jax.tree.leaves(a.posterior), jax.tree.leaves(b.posterior), strict=True):
        np.testing.assert_allclose(np.asarray(u), np.asarray(w), rtol=2e-5, atol=1e-5)
    np.testing.assert_allclose(float(ia.elbo), float(ib.elbo), rtol=1e-5)


def test_a_point_with_no_component_near_is_not_learned():
    """Points whose pool is empty (nothing of the map projects near them) get weight 0
    and are counted out by the reach, as the KD-tree's far points are."""
    cam, prior, xyz, rgb = _few_components()
    far = np.array([[0.0, 0.0, 0.5]], np.float32)  # in front of the wall, off every list
    pj = Stepper(prior, estep="sparse", n_candidates=C, search="projective", spacing=0.6,
                 reach=1.0)
    pj.tiling = projective.Tiling(32, 32, 4, 16, C)
    pts = np.concatenate([xyz[:20], far * 0 + [[5.0, 5.0, 2.0]]]).astype(np.float32)
    cols = np.concatenate([rgb[:20], rgb[:1]])
    _, info = pj(model.start(prior), pts, cols, camera=cam)
    assert info.learned[:20].all() and not info.learned[20]


def test_a_point_with_no_component_listed_takes_the_kdtree_nearest_without_a_reach():
    """With no reach (a fixed reference), a point whose pool is empty is learned as the
    KD-tree would learn it, from its nearest means (never from the -1 entries of its
    empty list, whose statistics would go to component 0): what it adds equals the
    KD-tree stepper's statistics of that point alone."""
    cam, prior, xyz, rgb = _few_components()
    pj = Stepper(prior, estep="sparse", n_candidates=C, search="projective", spacing=0.6)
    pj.tiling = projective.Tiling(32, 32, 4, 16, C)
    far = np.array([[5.0, 5.0, 2.0]], np.float32)
    pts = np.concatenate([xyz[:20], far]).astype(np.float32)
    cols = np.concatenate([rgb[:20], rgb[:1]])
    with_far, _ = pj(model.start(prior), pts, cols, camera=cam)
    without, _ = pj(model.start(prior), pts[:20], cols[:20], camera=cam)
    kd = Stepper(prior, estep="sparse", n_candidates=C, search="kdtree")
    alone, _ = kd(model.start(prior), far, rgb[:1])
    for u, w, a in zip(jax.tree.leaves(with_far.stats), jax.tree.leaves(without.stats),
                       jax.tree.leaves(alone.stats), strict=True):
        np.testing.assert_allclose(np.asarray(u) - np.asarray(w), np.asarray(a), rtol=1e-5,
                                   atol=1e-5)


def test_a_few_missed_points_are_left_without_building_the_tree():
    """At most MISSED_SHARE of a frame's points missed by every list: they stay unlearned
    and no KD-tree is built (one over every mean costs more than they can add)."""
    from vbgs.inference.stepper import MISSED_SHARE

    cam, prior, xyz, rgb = _few_components()
    many = int(np.ceil(1.0 / MISSED_SHARE))
    pts = np.concatenate([np.tile(xyz, (many // len(xyz) + 1, 1))[:many],
                          [[5.0, 5.0, 2.0]]]).astype(np.float32)
    cols = np.tile(rgb[:1], (len(pts), 1))
    pj = Stepper(prior, estep="sparse", n_candidates=C, search="projective", spacing=0.6,
                 reach=10.0)
    pj.tiling = projective.Tiling(32, 32, 4, 16, C)
    _, info = pj(model.start(prior), pts, cols, camera=cam)
    assert info.learned[:-1].all() and not info.learned[-1] and pj._tree is None


def test_projective_stream_of_a_fixed_reference_is_order_free(scene):
    """Under prior assignment with a fixed reference the candidates depend on the
    reference and the frame only: the frames in reverse order give the same posterior."""
    config = mapping.Config(components=400, search="projective")
    xyz, rgb = (np.concatenate(a) for a in zip(
        *(unproject(f.camera, f.rgb, f.depth) for f in scene.train[:6]), strict=True))
    prior = model.init(xyz, rgb, 400, key=jax.random.key(0), scheme="data",
                       config=config.prior, bounds=scene.bounds)

    def run(frames):
        state = mapping.init(config, key=jax.random.key(0), prior=prior)
        for frame in frames:
            state, _ = mapping.update(state, frame, config)
        return state.mixture.posterior

    a, b = run(scene.train[:6]), run(scene.train[:6][::-1])
    for u, w in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(u), np.asarray(w), rtol=1e-4, atol=1e-4)


def test_bad_settings_are_refused():
    _, prior, _, _ = _few_components()
    with pytest.raises(ValueError, match="projective search .* spacing"):
        Stepper(prior, estep="sparse", search="projective")
    with pytest.raises(ValueError, match="search must be one of auto, kdtree, projective"):
        mapping.Config(search="octree")


def test_tiles_are_few_enough_at_a_sensors_size():
    """At most TILES_ACROSS tiles across the shorter side: 8 pixels at 640 x 480 (4 on
    its stride-2 lattice, the same patch of the scene), while a 128-pixel frame keeps the
    spacing's tiles (MIN_TILE where the components are dense)."""
    from vbgs.render.camera import from_fov, look_at
    pose = look_at((0.0, -2.0, 0.5), (0.0, 0.0, 0.5))
    dense = 1e-4  # world units: a spacing far under a pixel
    assert projective.tile_size(from_fov(640, 480, 1.0, pose), dense, 2.0) == 8
    assert projective.tile_size(from_fov(320, 240, 1.0, pose), dense, 2.0) == 4
    assert projective.tile_size(from_fov(128, 128, 1.0, pose), dense, 2.0) == projective.MIN_TILE
    # a coarse spacing still sets larger tiles (the frame's quarter at most)
    assert projective.tile_size(from_fov(640, 480, 1.0, pose), 0.5, 2.0) > 8


def test_tile_lists_are_each_tiles_nearest_in_depth_order():
    """The lists against a sort written out over (tile, depth, slot): a tile crowded past
    ``L`` keeps its nearest, equal depths list the lower slot first, and components
    behind the camera, outside the tiled area or inactive are listed nowhere."""
    rng = np.random.default_rng(3)
    tiling = projective.Tiling(width=24, height=16, tile=4, list_length=5, n_candidates=3)
    k = 400
    u = np.concatenate([rng.uniform(-10.0, 34.0, k - 40), np.full(40, 9.5)])  # 40 in one tile
    v = np.concatenate([rng.uniform(-10.0, 26.0, k - 40), np.full(40, 6.5)])
    z = np.round(rng.uniform(0.5, 3.0, k), 1).astype(np.float32)  # many equal depths
    front = rng.random(k) < 0.9
    active = rng.random(k) < 0.9
    seen = projective.Projected(jnp.asarray(u, jnp.float32), jnp.asarray(v, jnp.float32),
                                jnp.asarray(np.where(front, z, 1.0)), jnp.asarray(front))
    lists, count = projective.tile_lists(seen, jnp.asarray(active), tiling)
    tx, ty = np.floor(u / 4).astype(int) + 1, np.floor(v / 4).astype(int) + 1
    listed = (front & active & (tx >= 0) & (tx < tiling.tiles_x) & (ty >= 0)
              & (ty < tiling.tiles_y))
    tile = ty * tiling.tiles_x + tx
    for t in range(tiling.tiles_x * tiling.tiles_y):
        here = np.flatnonzero(listed & (tile == t))
        want = here[np.lexsort((here, z[here]))][:5]
        assert int(count[t]) == len(want)
        assert np.array_equal(np.asarray(lists[t]), np.pad(want, (0, 5 - len(want)),
                                                           constant_values=-1))
    assert int(count[tiling.tiles_x * 2 + 3]) == 5  # the crowded tile, cut at L
