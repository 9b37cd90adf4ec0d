"""``--method vbgs-polish``: VBGS, then the baseline's steps from its splats, anchored to
the posterior."""

import json
from dataclasses import replace

import numpy as np
import pytest

from experiments.learners import PolishLearner, VbgsLearner
from experiments.learners.polish_learner import anchored_seen_step, draw_points
from experiments.tasks.protocol import stream_frames
from experiments.run import main
from experiments.tasks.scene_task import SceneTask, prepare_scene
from vbgs.baseline.anchor import ANCHOR_WEIGHT, anchor_terms
from vbgs.baseline.params import params_from_splats, trainable
from vbgs.compilation import enable_persistent_cache
from vbgs.data.streams import stream_order
from vbgs.render.raster import rasterize

TINY = dict(size=24, frames=4, n_test=1, n_val=0, components=300, method="vbgs-polish")
STEPS = 20  # one step count: the compiled step is shared by the tests's learners


@pytest.fixture(scope="module", autouse=True)
def compile_cache():
    """Compiled steps from the persistent cache, as the command line has them."""
    enable_persistent_cache()


@pytest.fixture(scope="module")
def scene():
    return prepare_scene(SceneTask(**TINY))[0]


@pytest.fixture(scope="module")
def started(scene):
    """A static polish before its first step, and the frames and background it trains on."""
    task = SceneTask(**TINY, protocol="static", steps=STEPS)
    learner = PolishLearner(task, scene)
    frames = learner.static_frames(scene)
    background = list(stream_frames(task, scene, stream_order(4, task.order)))[-1][2]
    return learner, frames, background


def test_zero_steps_render_vbgs_picture(scene, started):
    learner, _, background = started
    vbgs = VbgsLearner(SceneTask(**{**TINY, "method": "vbgs"}), scene)
    for _, frame, bg in stream_frames(vbgs.task, scene, stream_order(4, vbgs.task.order)):
        vbgs.learn(frame, bg)
    camera = scene.test[0].camera
    kw = dict(background=background, blur=learner.blur, capacity=1024)
    ours = np.asarray(rasterize(learner.splats(), camera, **kw).rgb)
    theirs = np.asarray(rasterize(vbgs.splats(), camera, **kw).rgb)
    assert ours.std() > 0.05  # a picture, not a blank
    np.testing.assert_allclose(ours, theirs, atol=1e-5)
    # and the anchor costs nothing there
    assert float(np.abs(anchor_terms(trainable(learner.state.params), learner.anchor)).max()) < 1e-3


def test_polish_steps_reduce_the_training_loss(started):
    learner, frames, background = started
    learner.train(frames[:1], STEPS, background)  # one frame: the losses are comparable
    losses = np.concatenate(learner.losses)
    assert losses.size == STEPS
    assert losses[-3:].mean() < 0.9 * losses[0]


@pytest.mark.slow
def test_a_strong_anchor_holds_the_splats_at_the_posterior(scene, started):
    _, frames, background = started
    moved = {}
    for weight in (0.0, 100.0):
        task = SceneTask(**TINY, protocol="static", steps=STEPS, polish_anchor=weight)
        learner = PolishLearner(task, scene)
        learner.static_frames(scene)
        drawn = np.asarray(learner.splats().opacities) > 0.01
        start = np.asarray(learner.splats().means)[drawn]
        learner.train(frames, STEPS, background)
        moved[weight] = np.abs(np.asarray(learner.splats().means)[drawn] - start).mean()
    assert moved[0.0] > 1e-4
    assert moved[100.0] < 0.5 * moved[0.0]


def test_continual_polish_with_fifo_replay(capsys):
    code = main(["fit-scene", "--method", "vbgs-polish", "--replay", "fifo:2",
                 "--steps-per-frame", "3", "--size", "24", "--components", "300",
                 "--frames", "4", "--test-views", "1", "--json"])
    assert code == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    frame_bytes = 24 * 24 * 4 * 4  # rgb + depth, float32
    assert record["replay_bytes"] == 2 * frame_bytes
    assert record["steps_total"] == 4 * 3
    assert record["seconds_vbgs"] > 0 and record["seconds_polish"] > 0
    assert record["seconds"] == pytest.approx(record["seconds_vbgs"] + record["seconds_polish"])
    assert record["psnr"] > 18.3  # measured 19.21 dB


def test_the_anchor_is_per_point_of_the_frames_drawn(scene):
    """Continual, FIFO of 2: after 4 frames the steps draw from 3, so the anchor weighs
    ANCHOR_WEIGHT per point of 3 frames' worth (4/3 times the old per-point-of-all
    weight), holds the polish where the frames before left it, and the step moves only
    what the drawn frame sees."""
    assert draw_points(1200.0, 30, 9) == 360.0  # 9 frames of 40 points
    assert draw_points(1200.0, 30, 30) == 1200.0  # static: every frame, every point
    task = SceneTask(**TINY, replay="fifo:2", steps_per_frame=3)
    learner = PolishLearner(task, scene)
    for _, frame, background in stream_frames(task, scene, stream_order(4, task.order)):
        learner.learn(frame, background)
    mix = learner.vbgs.state.mixture
    points = float(np.sum(mix.posterior.alpha - mix.prior.alpha))
    assert learner.vbgs.state.n_frames == 4
    np.testing.assert_allclose(float(learner.anchor.weight), ANCHOR_WEIGHT * 4 / (3 * points),
                               rtol=1e-5)
    assert learner._step_fn is anchored_seen_step
    # the centre is the polish as frames 1-3 left it (carried), not the posterior's splats
    posterior = params_from_splats(learner.vbgs.splats())
    assert float(np.abs(learner.anchor.base.means - posterior.means).max()) > 1e-4
    assert PolishLearner(replace(task, protocol="static", replay="none"),
                         scene)._step_fn is not anchored_seen_step


def test_static_polish_refuses_a_replay_buffer(capsys):
    code = main(["fit-scene", "--method", "vbgs-polish", "--protocol", "static",
                 "--replay", "fifo:2", "--size", "16", "--components", "50", "--frames", "2",
                 "--json"])
    assert code == 2
    assert "--replay fifo:2 has no meaning under --protocol static" in json.loads(
        capsys.readouterr().out.strip().splitlines()[-1])["error"]


def test_anchor_flag_is_the_polish_s_alone(capsys):
    code = main(["fit-scene", "--method", "gradient", "--anchor", "0.5", "--size", "16",
                 "--components", "50", "--frames", "2", "--json"])
    assert code == 2
    assert "--anchor" in capsys.readouterr().err


def test_images_have_no_polish():
    from experiments.tasks.image_task import ImageTask

    with pytest.raises(ValueError, match="scene learner"):
        ImageTask(method="vbgs-polish")
