"""vbgs.render.scale_fit: the splat scale chosen on the frames a map learned."""

import numpy as np
import pytest

from vbgs.data.formats import load_scene
from vbgs.render.camera import unproject
from vbgs.render.scale_fit import SCALES, choose_scale, rescaled
from vbgs.render.splats import Splats
from vbgs.render.views import render_view

WHITE = np.ones(3, np.float32)


@pytest.fixture(scope="module")
def splats_and_views():
    """Splats on every other pixel's point of one view of the object (32 px), a pixel
    footprint across, and three views of the scene."""
    scene = load_scene("object", size=32, n_train=3, n_test=0, seed=0)
    view = scene.train[0]
    xyz, rgb = unproject(view.camera, view.rgb, view.depth)
    xyz, rgb = xyz[::2], rgb[::2]
    side = float(np.median(np.asarray(view.depth)[view.depth > 0])) / view.camera.fx
    covs = np.broadcast_to((side**2) * np.eye(3, dtype=np.float32), (len(xyz), 3, 3))
    return Splats(xyz, covs.copy(), rgb, np.ones(len(xyz), np.float32)), scene.train


def test_rescaled_multiplies_covariances_by_the_squared_ratio(splats_and_views):
    splats, _ = splats_and_views
    out = rescaled(splats, 1.2, 1.5)
    np.testing.assert_allclose(np.asarray(out.covs), np.asarray(splats.covs) * 1.5625,
                               rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(rescaled(splats, 1.2, 1.2).covs),
                                  np.asarray(splats.covs))


@pytest.mark.parametrize("truth", [1.0, 1.35, 1.5])
def test_the_scale_the_frames_were_drawn_at_is_chosen(splats_and_views, truth):
    """Frames drawn from the splats at a scale of the grid: that scale scores best (its
    renders equal the frames) and is chosen."""
    splats, views = splats_and_views
    frames = [f._replace(rgb=render_view(rescaled(splats, 1.2, truth), f, WHITE).rgb)
              for f in views]
    scale, scores = choose_scale(splats, frames, WHITE, 0.3, 1.2)
    assert scale == truth and len(scores) == len(SCALES)
    assert np.argmax(scores) == SCALES.index(truth)


def test_a_tie_goes_to_the_base_scale_and_no_frames_are_refused(splats_and_views):
    splats, views = splats_and_views
    blank = splats._replace(opacities=np.zeros(splats.count, np.float32))
    frames = [f._replace(rgb=np.broadcast_to(WHITE, f.rgb.shape).copy()) for f in views]
    scale, scores = choose_scale(blank, frames, WHITE, 0.3, 1.2)
    assert scale == 1.2 and len(set(scores)) == 1
    with pytest.raises(ValueError, match="no frames to choose a splat scale on"):
        choose_scale(splats, [], WHITE, 0.3, 1.2)


def test_the_base_stays_unless_another_scale_draws_the_frames_clearly_better(
        splats_and_views):
    """A scale replaces the base only by more than ``margin`` dB: frames drawn at 1.1
    pick 1.1 with no margin and keep 1.2 with a margin above the gain."""
    splats, views = splats_and_views
    frames = [f._replace(rgb=0.98 * render_view(rescaled(splats, 1.2, 1.1), f, WHITE).rgb
                         + 0.01) for f in views]  # not equal: every score finite
    scale, scores = choose_scale(splats, frames, WHITE, 0.3, 1.2, margin=0.0)
    assert np.all(np.isfinite(scores))
    assert scale == 1.1
    gain = scores[SCALES.index(1.1)] - scores[SCALES.index(1.2)]
    assert gain > 0
    assert choose_scale(splats, frames, WHITE, 0.3, 1.2, margin=gain + 1e-6)[0] == 1.2
    assert choose_scale(splats, frames, WHITE, 0.3, 1.2, margin=gain - 1e-6)[0] == 1.1
