"""The gradient baseline: params, loss, one compiled step, densification, replay buffers."""

import dm_pix
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from vbgs.baseline import (
    DensifyConfig,
    TrainConfig,
    Trainer,
    camera_extent,
    frame_arrays,
    frame_loss,
    init_params,
    learning_rates,
    make_optimizer,
    make_step,
    params_from_prior,
    parse_replay,
    relocate,
    reset_moments,
    seen_rows,
    to_splats,
    trainable,
)
from vbgs.baseline.image import (
    centred,
    centred_pixels,
    fit_image,
    image_candidates,
    render_dense,
    render_sparse,
)
from vbgs.baseline.loss import depth_loss, ssim_of
from vbgs.baseline.train import ADAM
from vbgs.data.synthetic import object_scene
from vbgs.inference import model
from vbgs.render.camera import unproject
from vbgs.render.metrics import SSIM_SIGMA
from vbgs.render.raster import rasterize

K = 300  # splats in the tiny scene


@pytest.fixture(scope="module")
def tiny():
    """A 32x32 object scene (6 train, 2 test views) and K splats from the VBGS data init."""
    scene = object_scene(size=32, n_train=6, n_test=2, seed=0)
    xyz, rgb = (np.concatenate(a) for a in zip(
        *[unproject(f.camera, f.rgb, f.depth) for f in scene.train], strict=True))
    prior = model.init(xyz, rgb, K, key=jax.random.key(0), scheme="data", bounds=scene.bounds)
    extent = camera_extent([f.camera.position for f in scene.train])
    return scene, prior, params_from_prior(prior), extent


# --------------------------------------------------------------------------- params


def test_params_start_where_vbgs_starts(tiny):
    _, prior, params, _ = tiny
    np.testing.assert_allclose(params.means, prior.space.mean + prior.origin, rtol=1e-6)
    np.testing.assert_allclose(jax.nn.sigmoid(params.colour_logits), prior.colour.mean,
                               atol=1e-2)  # 16 of 60 broad splats: close
    cov = np.asarray(to_splats(params).covs)
    prior_cov = np.asarray(prior.space.scale / (prior.space.dof - 4.0)[:, None, None])
    np.testing.assert_allclose(cov, prior_cov, rtol=1e-4, atol=1e-9)


def test_capacity_padding_and_inactive_rows_render_transparent():
    means = np.random.default_rng(0).normal(size=(5, 3)).astype(np.float32)
    params = init_params(means, np.full((5, 3), 0.5), 0.1, capacity=8,
                         active=[True, True, False, True, True])
    assert params.means.shape == (8, 3) and params.rotations.shape == (8, 4)
    assert np.asarray(params.active).tolist() == [True, True, False, True, True] + [False] * 3
    opac = np.asarray(to_splats(params).opacities)
    assert np.all(opac[~np.asarray(params.active)] == 0) and np.all(opac[params.active] > 0)
    with pytest.raises(ValueError, match="capacity"):
        init_params(means, np.full((5, 3), 0.5), 0.1, capacity=3)


def test_learning_rates_follow_3dgs_defaults():
    cfg = TrainConfig(lr_decay_steps=100)
    rates = learning_rates(cfg, extent=2.0)
    np.testing.assert_allclose(rates.means(0), 1.6e-4 * 2.0, rtol=1e-6)
    np.testing.assert_allclose(rates.means(50), np.sqrt(1.6e-4 * 1.6e-6) * 2.0, rtol=1e-5)
    np.testing.assert_allclose(rates.means(10_000), 1.6e-6 * 2.0, rtol=1e-5)
    assert (rates.colour_logits, rates.opacity_logits, rates.log_scales, rates.rotations) == (
        2.5e-3, 5e-2, 5e-3, 1e-3)


# --------------------------------------------------------------------------- loss


def test_fast_ssim_equals_dm_pix():
    rng = np.random.default_rng(1)
    a, b = (jnp.asarray(rng.uniform(size=(24, 20, 3)), jnp.float32) for _ in range(2))
    reference = dm_pix.ssim(a, b, max_val=1.0, filter_size=11, filter_sigma=SSIM_SIGMA)
    np.testing.assert_allclose(ssim_of(a, b), reference, atol=1e-6)


def test_depth_loss_is_alpha_normalised_and_masked():
    target = jnp.array([[2.0, 0.0], [3.0, 4.0]])  # one invalid pixel
    alpha = jnp.array([[0.8, 0.9], [0.9, 0.1]])  # the last pixel is not covered
    depth_sum = alpha * jnp.array([[2.5, 9.0], [3.0, 1.0]])  # surfaces 2.5, -, 3.0, -
    np.testing.assert_allclose(depth_loss(depth_sum, alpha, target), 0.5 / 2, rtol=1e-6)


_jit_frame_loss = jax.jit(frame_loss)


def _mean_loss(params, frames, background):
    splats = to_splats(params)
    return float(np.mean([_jit_frame_loss(rasterize(splats, f.camera, background=background),
                                          f.rgb, f.depth) for f in frames]))


def test_loss_decreases_and_the_step_compiles_once(tiny):
    """30 steps over 6 frames (a relocation half way) reuse one compiled step.

    (The settings match the tiny continual run of tests/experiments/test_gradient_task.py,
    so a test session compiles this step once for both files.)
    """
    scene, _, params, extent = tiny
    cfg = TrainConfig(lr_decay_steps=30, depth_weight=0.1)
    trainer = Trainer(cfg, extent=extent)
    state = trainer.init(params, key=jax.random.key(1))
    before = _mean_loss(state.params, scene.train, scene.background)
    background = jnp.asarray(scene.background, jnp.float32)  # as the scene learner passes it
    state, first = trainer.train(state, scene.train, 15, background)
    state = trainer.densify(state)  # new values, same shapes and dtypes
    state, second = trainer.train(state, scene.train, 15, 0.5 * background)  # no recompile
    after = _mean_loss(state.params, scene.train, scene.background)
    assert np.all(np.isfinite(np.concatenate([first, second])))
    assert after < 0.9 * before, (before, after)
    assert trainer.step_fn._cache_size() == 1


def test_trace_counter_sees_a_single_trace():
    """The step's own trace hook: frames with different cameras and contents, one trace."""
    params = init_params(np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.1]]), np.full((2, 3), 0.5), 0.2)
    scene = object_scene(size=8, n_train=3, n_test=0)
    cfg = TrainConfig(densify=None)
    optimizer = make_optimizer(cfg, 1.0)
    traces = []
    step = make_step(cfg, optimizer, on_trace=lambda: traces.append(1))
    opt_state = optimizer.init(trainable(params))
    for i, frame in enumerate(scene.train):
        background = np.full(3, 0.3 * i, np.float32)  # re-estimated backgrounds: no retrace
        params, opt_state, loss = step(params, opt_state, *frame_arrays(frame), background)
    assert np.isfinite(float(loss)) and len(traces) == 1


def test_seen_only_step_leaves_unseen_splats_and_their_moments():
    """Two splats, the second far outside the view: with ``seen_only`` a penalty on both
    moves only the first, and the second's Adam moments stay zero; without, both move."""
    frame = object_scene(size=8, n_train=1, n_test=0).train[0]
    params = init_params(np.array([[0.0, 0.0, 0.0], [50.0, 50.0, 50.0]]),
                         np.full((2, 3), 0.5), 0.2)
    theta = trainable(params)
    assert seen_rows(theta).tolist() == [True, True]  # every row of nonzero leaves
    assert seen_rows(jax.tree.map(lambda x: x.at[1].set(0.0), theta)).tolist() == [True, False]
    cfg = TrainConfig(densify=None)
    optimizer = make_optimizer(cfg, 1.0)
    target = jnp.full((2, 3), 1.0)

    def pull(theta, target):  # every row pulled towards `target`
        return jnp.sum((theta.means - target) ** 2)

    moved = {}
    for seen_only in (True, False):
        step = make_step(cfg, optimizer, penalty=pull, seen_only=seen_only)
        p, opt_state = params, optimizer.init(theta)
        for _ in range(3):
            p, opt_state, loss = step(p, opt_state, *frame_arrays(frame), np.zeros(3), target)
        moved[seen_only] = np.abs(np.asarray(p.means - params.means)).max(-1)
        mu = np.asarray(opt_state[ADAM].mu.means)
        assert np.isfinite(float(loss)) and np.abs(mu[0]).max() > 0
        assert (np.abs(mu[1]).max() == 0) == seen_only
    assert moved[True][0] > 1e-4 and moved[True][1] == 0.0
    assert moved[False][1] > 1e-4


# --------------------------------------------------------------------------- densify


def _densify_case():
    """12 rows: 4 live (opacity 0.5), 4 dead (1e-4), 4 inactive; far-apart live splats."""
    means = np.zeros((8, 3), np.float32)
    means[:4, 0] = [0.0, 10.0, 20.0, 30.0]
    means[4:, 1] = 100.0  # dead ones sit far away from everything live
    params = init_params(means, np.full((8, 3), 0.5), 0.05, capacity=12, opacity=0.5)
    logits = params.opacity_logits.at[4:8].set(jnp.log(1e-4))
    return params._replace(opacity_logits=logits)


def test_relocation_moves_dead_splats_onto_live_ones_without_shape_changes():
    params = _densify_case()
    cfg = DensifyConfig(grow_rate=0.5)  # floor(0.5 * 4 live) = 2 inactive rows grow
    new, changed = relocate(params, jax.random.key(0), config=cfg)
    assert jax.tree.map(jnp.shape, new) == jax.tree.map(jnp.shape, params)
    active = np.asarray(new.active)
    assert active[:10].all() and not active[10:].any()
    moved = np.arange(4, 10)
    means = np.asarray(new.means)
    dist = np.linalg.norm(means[moved, None] - np.asarray(params.means)[None, :4], axis=-1)
    assert dist.min(1).max() < 5 * 0.05  # each moved row sits on a live source
    opac = np.asarray(jax.nn.sigmoid(new.opacity_logits))
    assert np.all(opac[moved] > cfg.dead_opacity)
    # a source split into N keeps its stacked alpha: 1 - (1 - o')^N = o
    src = dist.argmin(1)
    for s in np.unique(src):
        n = 1 + np.sum(src == s)
        np.testing.assert_allclose(1 - (1 - opac[s]) ** n, 0.5, rtol=1e-4)
    assert np.asarray(changed)[moved].all() and not np.asarray(changed)[10:].any()


def test_relocation_by_gradient_score_and_moment_reset():
    params = _densify_case()
    score = jnp.zeros(12).at[2].set(1.0)  # only live row 2 has gradient
    new, changed = relocate(params, jax.random.key(3), score,
                            config=DensifyConfig(sample_by="gradient", grow_rate=0.0))
    dist = np.linalg.norm(np.asarray(new.means)[4:8] - np.asarray(params.means)[2], axis=-1)
    assert np.all(dist < 5 * 0.05)
    opt_state = make_optimizer(TrainConfig(), 1.0).init(trainable(params))
    adam = opt_state[ADAM]._replace(mu=jax.tree.map(jnp.ones_like, opt_state[ADAM].mu))
    opt_state[ADAM] = adam
    reset = reset_moments(opt_state, changed)[ADAM]
    mu = np.asarray(reset.mu.means)
    assert np.all(mu[np.asarray(changed)] == 0) and np.all(mu[~np.asarray(changed)] == 1)


def test_relocation_with_nothing_live_is_a_no_op():
    params = _densify_case()
    params = params._replace(opacity_logits=jnp.full(12, -20.0))
    new, changed = relocate(params, jax.random.key(0))
    assert not np.asarray(changed).any()
    np.testing.assert_array_equal(new.means, params.means)


# --------------------------------------------------------------------------- replay


def test_fifo_keeps_exactly_the_last_k():
    buf = parse_replay("fifo:3")
    for i in range(10):
        buf = buf.add(np.full(2, i, np.float32))
        assert len(buf) == min(i + 1, 3)
    assert [int(x[0]) for x in buf.items] == [7, 8, 9]


def test_none_and_full():
    none, full = parse_replay("none"), parse_replay("full")
    for i in range(7):
        none, full = none.add(np.float32(i)), full.add(np.float32(i))
    assert len(none) == 0 and none.nbytes == 0
    assert [float(x) for x in full.items] == list(range(7))


def test_reservoir_is_uniform_over_the_stream():
    n, k, streams = 20, 5, 2000
    counts = np.zeros(n)
    for seed in range(streams):
        buf = parse_replay(f"reservoir:{k}", seed=seed)
        for i in range(n):
            buf = buf.add(i)
        assert len(buf) == k and len(set(buf.items)) == k
        counts[list(buf.items)] += 1
    p = k / n
    chi2 = np.sum((counts - streams * p) ** 2 / (streams * p * (1 - p)))
    assert chi2 < stats.chi2.ppf(0.999, n - 1), counts
    # seeded: the same seed gives the same sample, another seed (almost surely) not
    a, b, c = (parse_replay("reservoir:3", seed=s) for s in (7, 7, 8))
    for i in range(30):
        a, b, c = a.add(i), b.add(i), c.add(i)
    assert a.items == b.items and a.items != c.items


def test_replay_bytes_count_rgb_and_depth(tiny):
    scene = tiny[0]
    per_frame = 32 * 32 * 3 * 4 + 32 * 32 * 4
    buf = parse_replay("fifo:2")
    for f in scene.train[:5]:
        buf = buf.add(frame_arrays(f))
    assert buf.nbytes == 2 * per_frame
    assert parse_replay("full").add(scene.train[0]).nbytes == per_frame


@pytest.mark.parametrize("spec, match", [
    ("fifo", "needs a size"), ("fifo:0", "needs a size"), ("reservoir:x", "needs a size"),
    ("lifo:3", "unknown replay"), ("none:3", "takes no size"), ("full:2", "takes no size"),
])
def test_replay_parse_errors_are_clear(spec, match):
    with pytest.raises(ValueError, match=match):
        parse_replay(spec)
    with pytest.raises(TypeError, match="string"):
        parse_replay(8)


# --------------------------------------------------------------------------- 2-D images


def _image_params(seed=0, k=60, size=16):
    rng = np.random.default_rng(seed)
    means = rng.uniform(0, size, (k, 2)).astype(np.float32)
    return init_params(means, rng.uniform(size=(k, 3)), 1.5)


def test_sparse_image_render_matches_dense_reference():
    params = _image_params()
    cand = image_candidates(params, 16, 16, n=16)
    xy, shifted = centred_pixels(16, 16), centred(params, 16, 16)
    np.testing.assert_allclose(render_sparse(shifted, xy, cand), render_dense(shifted, xy),
                               atol=1e-2)  # 16 of 60 broad splats: close
    full = image_candidates(params, 16, 16, n=60)  # every splat: exact
    np.testing.assert_allclose(render_sparse(shifted, xy, full), render_dense(shifted, xy),
                               atol=1e-5)


def test_image_fit_reduces_the_loss():
    rng = np.random.default_rng(2)
    image = np.clip(rng.uniform(size=(4, 4, 3)).repeat(4, 0).repeat(4, 1), 0, 1)
    _, losses = fit_image(_image_params(), image.astype(np.float32), steps=30,
                          key=jax.random.key(0))
    assert losses.shape == (30,) and losses[-5:].mean() < 0.8 * losses[:5].mean()


def test_measured_depth_weighs_far_noisy_pixels_less():
    """Kinect depth: the depth L1's pixel weights fall as sigma_z grows with the depth,
    average about 1 over the pixels with depth, and change the loss only through them."""
    import jax.numpy as jnp

    from vbgs.baseline.loss import depth_loss
    from vbgs.mapping.measurement import depth_weights
    from vbgs.render.camera import from_fov

    cam = from_fov(16, 16, np.deg2rad(60), np.eye(4))
    depth = np.tile(np.linspace(1.0, 4.0, 16, dtype=np.float32), (16, 1))
    depth[:2] = 0.0  # holes
    w = depth_weights(depth, cam, "kinect")
    assert (np.diff(w[5]) < 0).all()  # farther, noisier: less weight
    assert np.median(w[depth > 0]) == pytest.approx(1.0, rel=0.02)
    assert (w[:2] == 1).all() and (depth_weights(depth, cam, "exact") == 1).all()
    alpha = jnp.ones((16, 16))
    rendered = jnp.asarray(depth) + 0.1  # 10 cm off everywhere
    plain = float(depth_loss(rendered, alpha, depth))
    weighted = float(depth_loss(rendered, alpha, depth, jnp.asarray(w)))
    assert plain == pytest.approx(0.1, rel=1e-4)
    assert weighted == pytest.approx(0.1 * w[depth > 0].mean(), rel=1e-4)
