"""vbgs.data.changing: scenes that change half-way through their stream."""

import numpy as np
import pytest

from vbgs.data.changing import changed_pixels
from vbgs.data.synthetic import changing_scene, make_scene


@pytest.mark.parametrize("base", ["object", "room", "walk"])
def test_the_first_state_is_the_static_scene_and_the_second_lap_differs(base):
    scene = changing_scene(base, size=24, n_train=6, n_test=2, n_val=1)
    static = make_scene(base, size=24, n_train=3, n_test=2, n_val=1)
    assert scene.name == f"{base}-change" and scene.changes == (3,)
    for a, b in zip(scene.train[:3], static.train, strict=True):  # the first lap, to the bit
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.depth, b.depth)
    for a, b in zip(scene.first_state, static.test, strict=True):
        np.testing.assert_array_equal(a.rgb, b.rgb)
    # the second lap walks the same path through the changed world
    for a, b in zip(scene.train[:3], scene.train[3:], strict=True):
        np.testing.assert_array_equal(a.camera.pose, b.camera.pose)
    share = np.mean([changed_pixels(a, b).mean()
                     for a, b in zip(scene.train[:3], scene.train[3:], strict=True)])
    assert 0.01 < share < 0.5  # some of the view changed, most did not


def test_changed_pixels_sees_colour_and_depth_apart():
    scene = changing_scene("object", size=16, n_train=2, n_test=1, n_val=0)
    a = scene.first_state[0]
    assert not changed_pixels(a, a).any()
    recoloured = a._replace(rgb=np.clip(a.rgb + 0.1, 0, 1))
    assert changed_pixels(a, recoloured)[a.rgb.max(-1) < 0.85].all()
    deeper = a._replace(depth=a.depth * 1.01)
    assert (changed_pixels(a, deeper) == (a.depth > 0)).all()


def test_bad_requests_are_refused():
    with pytest.raises(ValueError, match="no changing version of 'walk-long'"):
        changing_scene("walk-long")
    with pytest.raises(ValueError, match="n_train must be at least 2"):
        changing_scene("object", n_train=1)
