"""A world that changes (vbgs.mapping.change): what was removed loses its components
within a few frames that see through it, what moved appears at its new place, and a
static stream, noisy or exact, forgets nothing."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs import mapping
from vbgs.data.synthetic import changing_scene, make_scene
from vbgs.inference.grow import is_active
from vbgs.mapping import change
from vbgs.mapping.config import (EXACT_RECOLOUR_SIGMAS, RECOLOUR_GATE, EvidenceConfig,
                                 GrowthConfig, SensorConfig)
from vbgs.sensors import simulate

SIZE, FRAMES, K = 64, 24, 4000  # twelve frames a lap


def config(forget_after=change.FORGET_AFTER, sensor=SensorConfig(), recolour=None,
           shaped=change.SHAPED_POINTS, reference="history", gate=RECOLOUR_GATE):
    """The map's config, its defaults where not given (colour behind the gate with exact
    depth; ``recolour=0.0``: depth's evidence alone)."""
    return mapping.Config(components=K, sensor=sensor, evidence=EvidenceConfig(
        forget_after=forget_after, recolour_sigmas=recolour, shaped_points=shaped,
        recolour_reference=reference, recolour_gate=gate))


def repainted(frame):
    """A frame of the same world with every channel moved by half its range."""
    return frame._replace(rgb=(np.asarray(frame.rgb) + 0.5) % 1.0)


def stream(frames, cfg, background=None, each=None):
    state = mapping.init(cfg, key=jax.random.key(0))
    for frame in frames:
        state, _ = mapping.update(state, frame, cfg, background)
        if each is not None:
            each(state)
    return state


def mass_within(state, lo, hi) -> float:
    """Points' worth of statistics held by components whose mean lies in the box."""
    mean = np.asarray(state.mixture.posterior.space.mean) + np.asarray(
        state.mixture.prior.origin)
    count = np.asarray(state.mixture.stats.count, np.float64)
    inside = np.all((mean >= lo) & (mean <= hi), axis=1)
    return float(count[inside].sum())


@pytest.fixture(scope="module")
def changed():
    scene = changing_scene("object", size=SIZE, n_train=FRAMES, n_test=2, n_val=0)
    return scene


def old_crate():
    """Bounds about the crate's first place, which the changed object scene leaves empty
    (its jitter drawn as :func:`vbgs.data.synthetic.object_primitives` draws it)."""
    jy = np.random.default_rng(0).uniform(-0.05, 0.05, (3, 2))[1]
    centre = np.array([-0.40 + jy[0], 0.30 + jy[1], 0.30])
    return centre - 0.35, centre + 0.35


def test_a_removed_object_loses_its_mass_within_a_few_frames(changed):
    lo, hi = old_crate()
    lo[2] = 0.15  # clear of the platform's top, whose rays hit what touches it
    held = []
    stream(changed.train, config(), changed.background,
           each=lambda s: held.append(mass_within(s, lo, hi)))
    kept = []
    stream(changed.train, config(forget_after=0), changed.background,
           each=lambda s: kept.append(mass_within(s, lo, hi)))
    lap = changed.changes[0]
    assert held[lap - 1] == kept[lap - 1] > 100  # the crate was learned (same stream so far)
    after = lap + change.FORGET_AFTER + 3  # a few frames that see through it
    assert held[after] < 0.02 * held[lap - 1]  # measured 26 of 2071 points' worth
    assert held[-1] < 0.02 * held[lap - 1]
    assert kept[-1] > 0.9 * kept[lap - 1]  # without forgetting it stays


def test_the_far_side_along_a_ray_is_the_surface_it_crosses():
    """A flat component (a disc in the plane z = 2, seen down the camera's z axis from
    the origin, tilted 60 degrees about x): a ray off its centre passes its far side
    where it crosses the tilted plane, plus pass_sigmas of its thickness seen along the
    ray and the sensor's noise; the camera axis band is its whole extent."""
    from vbgs.render.opacity import _far_along_ray

    tilt = np.deg2rad(60.0)
    normal = np.array([0.0, np.sin(tilt), np.cos(tilt)])
    thickness, extent = 0.001, 0.2
    cov = extent**2 * (np.eye(3) - np.outer(normal, normal)) + thickness**2 * np.outer(
        normal, normal)
    mean = np.array([0.0, 0.0, 2.0])
    pose = np.eye(4)
    f, c = 100.0, 50.0
    u, v = c, 60.2  # read at pixel (50, 60), its centre's ray (0.005, 0.105, 1)
    ray = np.array([(np.floor(u) + 0.5 - c) / f, (np.floor(v) + 0.5 - c) / f, 1.0])
    cross = mean @ normal / (ray @ normal)  # where the ray meets the plane (camera depth)
    along = thickness / abs(ray @ normal)  # the thickness along the ray, per unit depth
    for sensor_var in (0.0, 0.01**2):
        far = _far_along_ray(jnp.asarray(mean[None], jnp.float32),
                             jnp.asarray(cov[None], jnp.float32),
                             jnp.asarray([sensor_var], jnp.float32), jnp.asarray(pose, jnp.float32),
                             f, f, c, c, 4.0, jnp.asarray([True]), jnp.asarray([9.0]))
        got = float(far(jnp.asarray([[[u, v]]], jnp.float32))[0, 0])
        expect = cross + 4.0 * np.sqrt(along**2 + sensor_var)
        assert abs(got - expect) < 1e-3 * expect, (got, expect)
    unshaped = _far_along_ray(jnp.asarray(mean[None], jnp.float32),
                              jnp.asarray(cov[None], jnp.float32), jnp.zeros(1),
                              jnp.asarray(pose, jnp.float32), f, f, c, c, 4.0,
                              jnp.asarray([False]), jnp.asarray([9.0]))
    assert float(unshaped(jnp.asarray([[[u, v]]], jnp.float32))[0, 0]) == 9.0


def test_a_moved_object_appears_at_its_new_place(changed):
    """Over the pixels whose colour or depth changed (the crate at its new place, the
    sphere gone, a new ball, a new texture), the final map draws the world as it is."""
    from vbgs.data.changing import changed_pixels
    from vbgs.render.metrics import psnr_of_mse
    from vbgs.render.raster import rasterize

    scores = {}
    for after in (change.FORGET_AFTER, 0):
        c = config(forget_after=after)
        splats = mapping.splats(stream(changed.train, c, changed.background), c)
        errors = []
        for first, view in zip(changed.first_state, changed.test, strict=True):
            image = np.asarray(rasterize(splats, view.camera,
                                         background=changed.background).rgb)
            mask = changed_pixels(first, view)
            errors.append(((image - np.asarray(view.rgb)) ** 2).mean(-1)[mask])
        scores[after] = psnr_of_mse(float(np.concatenate(errors).mean()))
    assert scores[change.FORGET_AFTER] > scores[0] + 2.0, scores  # measured 13.89 against 11.07


def test_a_repainted_world_is_learned_in_its_new_colours():
    """The object's second lap repainted, every channel moved by half its range (the same
    depth: only colour tells the change): forgetting recoloured components
    (``recolour_sigmas``), the final map draws the new colours, where without it (or with
    depth's evidence alone) each component keeps a blend of both laps."""
    from vbgs.render.metrics import psnr_of_mse
    from vbgs.render.raster import rasterize

    scene = make_scene("object", size=SIZE, n_train=FRAMES, n_test=2, n_val=0)
    lap = FRAMES // 2
    frames = scene.train[:lap] + [repainted(f) for f in scene.train[lap:]]
    background = (np.asarray(scene.background) + 0.5) % 1.0
    scores, forgotten = {}, {}
    for after in (change.FORGET_AFTER, 0):
        c = config(forget_after=after, recolour=4.0, gate=0.0)
        state = stream(frames, c, background)
        splats = mapping.splats(state, c)
        mse = [float(((np.asarray(rasterize(splats, v.camera, background=background).rgb)
                       - np.asarray(repainted(v).rgb)) ** 2).mean()) for v in scene.test]
        scores[after], forgotten[after] = psnr_of_mse(float(np.mean(mse))), state.n_forgotten
    assert forgotten[0] == 0 and forgotten[change.FORGET_AFTER] > 1000, (forgotten, scores)
    # measured 16.21 dB against 14.47: six frames of the twelve after the change relearn
    assert scores[change.FORGET_AFTER] > scores[0] + 1.3, scores
    # behind the default gate a world that changed only in colour is depth's alone
    assert stream(frames, config(), background).n_forgotten == 0


def test_a_static_stream_forgets_nothing_to_the_bit():
    scene = make_scene("object", size=SIZE, n_train=FRAMES, n_test=1, n_val=0)
    on = stream(scene.train, config(), scene.background)
    off = stream(scene.train, config(forget_after=0), scene.background)
    assert on.n_forgotten == 0
    for a, b in zip(jax.tree_util.tree_leaves(on.mixture), jax.tree_util.tree_leaves(off.mixture),
                    strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(np.asarray(on.evidence.hits), np.asarray(off.evidence.hits))


def test_a_static_noisy_stream_forgets_nothing():
    scene = make_scene("object", size=SIZE, n_train=FRAMES, n_test=1, n_val=0)
    frames = [f._replace(depth=simulate("kinect", f.depth, f.camera, seed=[0, i]))
              for i, f in enumerate(scene.train)]
    state = stream(frames, config(sensor=SensorConfig("kinect")), scene.background)
    assert state.n_forgotten == 0
    assert int(np.asarray(is_active(state.mixture.prior)).sum()) > 1000


@pytest.mark.parametrize("reference, sigmas", [("posterior", 6.0), ("map", 2.0)])
def test_judged_by_colour_a_static_stream_forgets_nothing_to_the_bit(reference, sigmas):
    """Colour read against each component's posterior at 6 sigmas of the distance
    expected where nothing changed, or against the map as a whole at 2 colour sigmas,
    forgets nothing on a static stream, exact or under the Kinect: the map is the one
    depth's evidence alone learns, to the bit."""
    scene = make_scene("object", size=SIZE, n_train=FRAMES, n_test=1, n_val=0)
    noisy = [f._replace(depth=simulate("kinect", f.depth, f.camera, seed=[0, i]))
             for i, f in enumerate(scene.train)]
    for frames, sensor in ((scene.train, SensorConfig()), (noisy, SensorConfig("kinect"))):
        on = stream(frames, config(sensor=sensor, recolour=sigmas, reference=reference,
                                   gate=0.0), scene.background)
        off = stream(frames, config(sensor=sensor, recolour=0.0), scene.background)
        assert on.n_forgotten == 0 and off.n_forgotten == 0
        for a, b in zip(jax.tree_util.tree_leaves(on.mixture),
                        jax.tree_util.tree_leaves(off.mixture), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_behind_a_colour_gate_a_static_stream_forgets_nothing_to_the_bit():
    """The history's colour test at 4 sigmas forgets rims of a static stream; behind a
    gate (``recolour_gate``) it forgets none until the depth has forgotten a share of
    the slots, which a static world never does: the map is depth's alone, to the bit."""
    scene = make_scene("object", size=SIZE, n_train=FRAMES, n_test=1, n_val=0)
    ungated = stream(scene.train, config(recolour=4.0, gate=0.0), scene.background)
    assert ungated.n_forgotten > 0  # the test has something to hold back
    on = stream(scene.train, config(recolour=4.0, gate=0.01), scene.background)
    off = stream(scene.train, config(recolour=0.0), scene.background)
    assert on.n_forgotten == 0 and off.n_forgotten == 0
    assert int(np.asarray(on.doubt.runs).max()) >= change.FORGET_AFTER  # held back
    for a, b in zip(jax.tree_util.tree_leaves(on.mixture),
                    jax.tree_util.tree_leaves(off.mixture), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_behind_a_colour_gate_a_changed_world_is_recoloured_once_depth_saw_change(changed):
    """The changing object: until its frames' depth has forgotten a share of the slots
    (the removed crate) the gated map forgets what depth alone forgets, frame by frame;
    from then on components recoloured six frames in a row are forgotten too."""
    gate = 0.01
    gated, depth = [], []
    stream(changed.train, config(recolour=4.0, gate=gate), changed.background,
           lambda state: gated.append(state.n_forgotten))
    stream(changed.train, config(recolour=0.0), changed.background,
           lambda state: depth.append(state.n_forgotten))
    opens = next(i for i, n in enumerate(depth) if n >= gate * K)
    assert gated[:opens] == depth[:opens]
    assert gated[-1] > depth[-1] > 0, (gated, depth)


def test_in_a_colour_run_of_its_own_the_posterior_reference_is_held():
    """Under a gate (colour counted apart), the posterior reference is held at the colour
    before the run while a run of recolourings lasts, as it is within a see-through run
    without one: the frames after a change do not drag the reference after them."""
    k = 2
    held = change.no_doubt(k)._replace(runs=jnp.array([2, 0], jnp.int32),
                                       colour=jnp.array([[0.2, 0.2, 0.2]] * k) * 20.0,
                                       weight=jnp.full(k, 20.0))
    mean, kappa = jnp.full((k, 3), 0.8), jnp.full(k, 50.0)
    ones = jnp.ones(k)
    out = change._posterior(held, ones, jnp.zeros(k, bool), jnp.ones(k, bool),
                            jnp.full((k, 3), 0.8), jnp.full(k, 5, jnp.int32), jnp.zeros(k),
                            mean, kappa, jnp.float32(4.0), jnp.float32(0.05), apart=True)
    reference = np.asarray(out.colour) / np.asarray(out.weight)[:, None]
    np.testing.assert_allclose(reference[0], 0.2, rtol=1e-6)  # held: the run goes on
    np.testing.assert_allclose(reference[1], 0.8, rtol=1e-6)  # no run: the posterior
    assert np.asarray(out.runs).tolist() == [3, 0] and np.asarray(out.frames).tolist() == [0, 0]


def test_a_colour_gate_is_a_share():
    for bad in (-0.1, 1.0, True):
        with pytest.raises(ValueError, match="recolour_gate"):
            EvidenceConfig(recolour_gate=bad)
    assert not change.gate_open(1000, K, 0.0)  # no gate: never
    assert not change.gate_open(0, K, 1e-9)  # at least one component forgotten by depth
    assert change.gate_open(40, K, 0.01) and not change.gate_open(39, K, 0.01)


def test_judged_against_its_posterior_a_repainted_surface_is_forgotten():
    """The object repainted after its first lap: against their posteriors, components are
    forgotten as soon as ``forget_after`` frames in a row have shown them another colour
    (none before), where depth alone forgets none."""
    scene = make_scene("object", size=SIZE, n_train=FRAMES, n_test=1, n_val=0)
    lap = FRAMES // 2
    frames = scene.train[:lap] + [repainted(f) for f in scene.train[lap:]]
    background = (np.asarray(scene.background) + 0.5) % 1.0
    counts = []
    stream(frames, config(recolour=6.0, reference="posterior", gate=0.0), background,
           each=lambda state: counts.append(state.n_forgotten))
    first = lap + change.FORGET_AFTER - 1  # the frame that completes the first run
    assert counts[first - 1] == 0 and counts[first] > 20, counts  # measured 29, then 36
    assert stream(frames, config(), background).n_forgotten == 0


def test_colour_is_read_by_default_with_exact_depth_only():
    """By default colour counts with exact depth, behind the gate (so the records of
    static scenes stay what they were: the gate never opens there), and not under a
    measured sensor; a tolerance that is not a number >= 0 is refused."""
    assert EvidenceConfig().recolour_sigmas is None
    assert EvidenceConfig().recolour_gate == RECOLOUR_GATE > 0
    assert mapping.Config(components=K).recolour_sigmas == EXACT_RECOLOUR_SIGMAS
    assert mapping.Config(components=K, sensor=SensorConfig("kinect")).recolour_sigmas == 0.0
    assert mapping.Config(components=K, sensor=SensorConfig("kinect"), evidence=EvidenceConfig(
        recolour_sigmas=2.0)).recolour_sigmas == 2.0
    with pytest.raises(ValueError, match="recolour_sigmas"):
        EvidenceConfig(recolour_sigmas=-1.0)
    with pytest.raises(ValueError, match="recolour_sigmas"):
        EvidenceConfig(recolour_sigmas=float("inf"))
    assert EvidenceConfig().recolour_reference == "history"
    with pytest.raises(ValueError, match="recolour_reference"):
        EvidenceConfig(recolour_reference="pixels")


def test_a_bad_setting_is_refused():
    with pytest.raises(ValueError, match="forget_after"):
        EvidenceConfig(forget_after=-1)
    with pytest.raises(ValueError, match="forget_after"):
        EvidenceConfig(forget_after=2.5)
    with pytest.raises(ValueError, match="shaped_points"):
        EvidenceConfig(shaped_points=-1.0)
    with pytest.raises(ValueError, match="growth.changed_refine"):
        GrowthConfig(changed_refine="yes")


def _with_and_without_changed_refine(scene):
    """Per frame of ``scene``'s stream with ``growth.changed_refine`` off and on: (components
    forgotten so far, empty slots after the frame, the map's leaves)."""
    runs = {}
    for on in (False, True):
        cfg = mapping.Config(components=K, growth=GrowthConfig(changed_refine=on))
        state, rows = mapping.init(cfg, key=jax.random.key(0)), []
        for frame in scene.train:
            state, _ = mapping.update(state, frame, cfg, scene.background)
            rows.append((state.n_forgotten, int((~is_active(state.mixture.prior)).sum()),
                         jax.tree_util.tree_leaves(state.mixture)))
        runs[on] = rows
    return runs[False], runs[True]


def _same_maps(off, on):
    for (_, empty_off, a), (_, empty_on, b) in zip(off, on, strict=True):
        assert empty_off == empty_on
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_once_the_world_is_seen_to_change_a_spent_budget_refines_with_every_slot_left():
    """The changing room at 4000 components spends its budget in the first lap: until a
    component is forgotten the stream is the one without the rule, to the bit; from then
    on a frame whose merges left fewer empty slots than refine_share of K refines with
    all of them, where the share kept most back (merges pay for the ground to come)."""
    scene = changing_scene("room", size=SIZE, n_train=FRAMES, n_test=1, n_val=0)
    off, on = _with_and_without_changed_refine(scene)
    first = next(i for i, (forgotten, _, _) in enumerate(on) if forgotten)
    _same_maps(off[:first], on[:first])
    left_on = sum(empty for _, empty, _ in on[first:])
    left_off = sum(empty for _, empty, _ in off[first:])
    assert left_on < 0.5 * left_off, (left_on, left_off)  # measured 103 against 398


def test_a_change_that_frees_many_slots_keeps_them_for_the_ground_to_come(changed):
    """The changing object forgets hundreds of components at 4000: more slots are empty
    than refine_share of K, so the share holds them and the stream is the one without
    the rule, to the bit."""
    off, on = _with_and_without_changed_refine(changed)
    assert on[-1][0] > 0.05 * K
    _same_maps(off, on)


def test_forgetting_is_a_new_prior_not_a_frames_evidence(changed):
    """The streaming bound of a frame that forgets components is read from the posterior
    that learned it, not the map after forgetting: the frames that forget stay on the
    scale of the others (read after forgetting, each forgotten component's KL back to its
    prior is that of all the data it held, millions of nats here)."""
    cfg = config()
    state = mapping.init(cfg, key=jax.random.key(0))
    per_point, forgot = [], []
    for frame in changed.train:
        n = state.n_forgotten
        state, info = mapping.update(state, frame, cfg, changed.background)
        b = mapping.bound(info, cfg)
        per_point.append(b.bound / b.n_points)
        forgot.append(state.n_forgotten > n)
    assert any(forgot) and not all(forgot)
    quiet = np.median([p for p, f in zip(per_point, forgot, strict=True) if not f])
    assert min(p for p, f in zip(per_point, forgot, strict=True) if f) > quiet - 20.0, (per_point, forgot)


def test_a_run_of_doubt_starts_only_on_an_opaque_component():
    """With ``doubt_opacity`` a see-through counts against a component only where its
    rays mostly hit it (a surface), or where a run has already begun; a component the
    rays pass more often than they hit (thinner than a pixel) is not doubted. Three
    components, all seen through this frame: opaque, thin, thin with a run under way."""
    from vbgs.render.opacity import Evidence, FrameEvidence

    k = 3
    seen = FrameEvidence(hits=jnp.zeros(k), passes=jnp.full(k, 5.0),
                         seen_through=jnp.ones(k, bool), shown=jnp.zeros((k, 3)),
                         n_shown=jnp.zeros(k, jnp.int32), spread=jnp.zeros(k),
                         blamed=jnp.zeros(k, jnp.int32))
    before = Evidence(hits=jnp.array([40.0, 27.0, 27.0]), passes=jnp.array([2.0, 48.0, 48.0]))
    doubt = change.no_doubt(k)._replace(frames=jnp.array([0, 0, 3], jnp.int32))
    active = jnp.ones(k, bool)
    every = change.observe(doubt, seen, before, active)
    np.testing.assert_array_equal(np.asarray(every.frames), [1, 1, 4])
    opaque = change.observe(doubt, seen, before, active, doubt_opacity=0.5)
    np.testing.assert_array_equal(np.asarray(opaque.frames), [1, 0, 4])


def test_doubted_only_where_opaque_a_removed_object_is_still_forgotten(changed):
    """At ``doubt_opacity`` 0.5 the crate taken away still loses its mass within a few
    frames that see through it: its components were surfaces its rays hit."""
    lo, hi = old_crate()
    lo[2] = 0.15
    held = []
    cfg = mapping.Config(components=K, evidence=EvidenceConfig(doubt_opacity=0.5))
    stream(changed.train, cfg, changed.background,
           each=lambda s: held.append(mass_within(s, lo, hi)))
    lap = changed.changes[0]
    assert held[lap - 1] > 100
    assert held[lap + change.FORGET_AFTER + 3] < 0.02 * held[lap - 1]


def test_doubt_opacity_is_an_opacity():
    assert EvidenceConfig().doubt_opacity is None
    assert mapping.Config().doubt_opacity == change.EXACT_DOUBT_OPACITY == 0.5
    assert mapping.Config(sensor=SensorConfig("kinect")).doubt_opacity == 0.0
    assert mapping.Config(evidence=EvidenceConfig(doubt_opacity=0.3)).doubt_opacity == 0.3
    for bad in (-0.1, 1.5, True, "half"):
        with pytest.raises(ValueError, match="doubt_opacity"):
            EvidenceConfig(doubt_opacity=bad)
