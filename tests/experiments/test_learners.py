"""Scene learners under the stream start: nothing read ahead, both methods start alike,
and the run's record carries the streaming bound."""

import contextlib
import io
import math

import numpy as np
import pytest

from experiments.learners import LEARNERS, GradientLearner, VbgsLearner
from experiments.tasks.protocol import frame_points
from experiments.tasks.scene_task import SceneTask, prepare_scene, run_scene
from vbgs import mapping
from vbgs.inference import grow


class FirstFrameOnly(list):
    """Training frames where only the first may be read (the others have not arrived)."""

    def __getitem__(self, i):
        if i != 0:
            raise AssertionError(f"frame {i} read before it arrived")
        return super().__getitem__(i)

    def __iter__(self):
        raise AssertionError("every frame read before they arrived")


def tiny(**kw) -> SceneTask:
    # the shapes of the other tiny object runs (32 px, 600 components, 2 test views:
    # test_fit_scene_cli, test_background_cli, test_bad_folders): their compiled learner
    settings = dict(size=32, frames=6, n_test=2, components=600, steps_per_frame=5)
    return SceneTask(**{**settings, **kw})


@pytest.fixture(scope="module")
def scene():
    return prepare_scene(tiny())[0]


@pytest.mark.parametrize("method", sorted(LEARNERS))
def test_stream_start_reads_only_the_frames_that_arrived(scene, method):
    guarded = scene._replace(train=FirstFrameOnly(scene.train))
    learner = LEARNERS[method](tiny(method=method), guarded)
    learner.learn(guarded.train[0], np.zeros(3, np.float32))
    assert 0 < learner.splats(drop_unused=True).count <= 600


def test_gradient_learner_grows_where_vbgs_grows(scene):
    task = tiny(method="gradient")
    vbgs, gradient = VbgsLearner(task, scene), GradientLearner(task, scene)
    for frame in scene.train[:3]:
        vbgs.state, _ = mapping.grow_components(vbgs.state, *frame_points(frame), vbgs.config)
        gradient._grow(frame)
        prior = vbgs.state.mixture.prior
        active = grow.is_active(prior)
        rows = np.asarray(gradient.state.params.active)
        assert rows.sum() == active.sum()
    # the same first-frame components; later frames are scored against each learner's own
    # (here: identical, untrained) means, so the same rows again
    np.testing.assert_allclose(np.asarray(gradient.state.params.means)[rows],
                               np.asarray(prior.space.mean + prior.origin)[active],
                               rtol=1e-6, atol=1e-6)


def test_vbgs_record_has_the_streaming_bound_when_asked():
    plain = run_scene(tiny()).to_dict()
    assert "stream_bound" not in plain and "stream_kl" not in plain  # a second E-step: opt-in
    result = run_scene(tiny(streaming_bound=True)).to_dict()
    assert result["init"] == "stream" and result["oracle_start"] is False
    assert result["psnr"] == plain["psnr"]  # a diagnostic: the map is the same
    per_batch = result["stream_bound_per_batch"]
    assert len(per_batch) == 6 and all(math.isfinite(b) for b in per_batch)
    assert result["stream_bound"] == pytest.approx(sum(per_batch), rel=1e-6)
    assert result["stream_bound"] == pytest.approx(
        result["stream_expected_loglik"] - result["stream_kl"], rel=1e-6)
    assert run_scene(tiny(init="data", frames=3)).oracle_start is True


@pytest.fixture(scope="module")
def room_past_its_budget():
    """The room's walkthrough spends the 300 components before frame 25 (at 32 px) and,
    without merging (which frees slots for it), leaves later ground unlearned: one run
    (:func:`run_scene`) gives the record, what it said on stderr and its VBGS learner."""
    from vbgs.mapping import GrowthConfig

    learners = []

    class Kept(VbgsLearner):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            learners.append(self)

    task = tiny(scene="room", frames=25, components=300, growth=GrowthConfig(merge=False),
                streaming_bound=True)
    err = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stderr(err):
        mp.setitem(LEARNERS, "vbgs", Kept)
        result = run_scene(task)
    (learner,) = learners
    return result, err.getvalue(), learner


def test_the_streaming_bound_counts_only_the_points_learned(room_past_its_budget):
    """Points beyond the stream start's reach are left out of the update, so the bound
    (what the model claims to explain) leaves them out too."""
    _, _, learner = room_past_its_budget
    state = learner.state
    assert state.n_unlearned > 0
    assert learner.bound.n_points == state.n_points - state.n_unlearned


def test_each_learner_is_scored_with_its_own_pixel_filter(scene):
    """VBGS splats are drawn with the task's splat_blur, the gradient baseline's with the
    filter it trained under: the record's renders are those renders."""
    from experiments.tasks.protocol import stream_protocol
    from vbgs.render.raster import BLUR_VARIANCE
    from vbgs.render.views import render_view

    assert GradientLearner.blur == BLUR_VARIANCE
    psnrs = {}
    for blur in (0.02, 0.3):
        task = tiny(splat_blur=blur)
        learner = VbgsLearner(task, scene)
        assert learner.blur == blur
        result = stream_protocol(task, scene, learner)
        background = np.asarray(result.background_rgb)
        rgb = render_view(learner.splats(), scene.test[0], background, blur).rgb
        np.testing.assert_allclose(result.images["render"][0], rgb, atol=1e-6)
        psnrs[blur] = result.psnr
    assert abs(psnrs[0.02] - psnrs[0.3]) > 0.05


@pytest.mark.parametrize("bad", [-0.1, float("nan"), 10.0])
def test_a_bad_pixel_filter_is_refused(bad):
    with pytest.raises(ValueError, match="splat_blur must be a pixel filter variance"):
        tiny(splat_blur=bad)


def test_points_left_unlearned_are_said_on_stderr(room_past_its_budget):
    """The share of the training points left unlearned is a field of the record and a
    warning."""
    result, err, _ = room_past_its_budget
    share = result.details["points_unlearned"]
    assert share > 0.01
    assert f"warning: {share:.1%} of the training points were not learned" in err
    assert "--components" in err


def test_the_record_says_the_median_points_a_component_holds(room_past_its_budget):
    """``points_per_component``: the median summed responsibilities of the components
    that learned any point (the room at 32 px: 300 components over 25 frames)."""
    result, _, learner = room_past_its_budget
    counts = np.asarray(learner.state.mixture.stats.count, np.float64)
    assert result.details["points_per_component"] == pytest.approx(
        np.median(counts[counts > 0]), rel=1e-12)
    assert result.details["points_per_component"] > 10  # 25 frames of 32 px on 300


@pytest.mark.parametrize("details, hint", [({"points_per_component": 5.8}, True),
                                           ({"points_per_component": 12.5}, False),
                                           ({"points_per_component": 5.8,
                                             "splat_scale_chosen": 1.5}, False),
                                           ({}, False)])
def test_uncovered_surface_is_said_and_small_splats_named(capsys, details, hint):
    """Background drawn over a test view's surface is said; with a median component of
    fewer than FEW_POINTS points and a fixed splat scale the warning also names small
    splats and what to try."""
    from experiments.tasks.scene_report import FEW_POINTS, UNCOVERED_WARNING, warn_uncovered

    warn_uncovered(UNCOVERED_WARNING / 2, details)
    assert capsys.readouterr().err == ""
    warn_uncovered(0.022, details)
    err = capsys.readouterr().err
    assert err.startswith("warning: 2.2% of the test views' pixels with a surface")
    assert ("splats too small" in err) is hint
    assert hint is (details.get("points_per_component", FEW_POINTS) < FEW_POINTS
                    and "splat_scale_chosen" not in details)
    if hint:
        assert "5.8 points" in err and "--splat-scale auto" in err and "--components" in err


def test_an_auto_splat_scale_is_chosen_on_the_arrived_frames_and_drawn():
    """``splat_scale="auto"``: the scale the kept arrived frames draw best, reported with
    each scale's score; the record is the run at that scale; the kept frames are counted."""
    from vbgs.render.scale_fit import SCALES

    result = run_scene(tiny(splat_scale="auto"))
    chosen, scores = result.details["splat_scale_chosen"], result.details["splat_scale_scores"]
    assert chosen in SCALES and scores[str(chosen)] == max(scores.values())
    fixed = run_scene(tiny(splat_scale=chosen))
    assert result.psnr == pytest.approx(fixed.psnr, abs=1e-3)
    frame = prepare_scene(tiny())[0].train[0]
    assert result.replay_bytes == 6 * (frame.rgb.nbytes + frame.depth.nbytes)  # all 6 < 12
    assert "splat_scale_chosen" not in fixed.details and fixed.replay_bytes == 0


@pytest.mark.parametrize("task, match", [
    (dict(splat_scale="big"), "splat_scale must be a positive number or 'auto'"),
    (dict(splat_scale=-1.0), "splat_scale must be a positive number or 'auto'"),
    (dict(splat_scale="auto", method="gradient"), "--method gradient takes a number")])
def test_a_bad_splat_scale_is_refused(task, match):
    with pytest.raises(ValueError, match=match):
        tiny(**task)
