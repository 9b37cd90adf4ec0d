"""A simulated sensor's holes set apart from its noise (``HoleSpec``, ``parse_holes``):
none, physical only, random at a rate whatever the level; the noise drawn is the same
whatever the holes, and the sensors that make no holes refuse a spec."""

import numpy as np
import pytest

from vbgs.render.camera import Camera
from vbgs.sensors import HOLED_SENSORS, HoleSpec, parse_holes, simulate


def scene_depth(size: int = 96):
    """A box in front of a wall (depth edges all round it) seen by a 100 px camera."""
    cam = Camera(100.0, 100.0, size / 2, size / 2, size, size, np.eye(4))
    depth = np.full((size, size), 3.0, np.float32)
    depth[size // 4: 3 * size // 4, size // 4: 3 * size // 4] = 2.0
    return depth, cam


def test_the_forms_parse_to_their_records():
    assert parse_holes("sensor") == HoleSpec() and HoleSpec().own
    assert parse_holes("none") == HoleSpec(physical=False, dropout=0.0)
    assert parse_holes("physical") == HoleSpec(physical=True, dropout=0.0)
    assert parse_holes("random:0.05") == HoleSpec(physical=False, dropout=0.05)
    assert parse_holes("physical+random:1") == HoleSpec(physical=True, dropout=1.0)
    assert HoleSpec().dropout_rate(0.02, 2.0) == 0.04  # the sensor's own: level x rate
    assert HoleSpec(dropout=0.1).dropout_rate(0.02, 0.0) == 0.1  # a given rate: any level


@pytest.mark.parametrize("bad", ["edges", "random:", "random:1.5", "random:-0.1",
                                 "random:nan", "physical+random:x", "none+random:0.1", ""])
def test_malformed_specs_are_refused_naming_the_forms(bad):
    with pytest.raises(ValueError, match="random"):
        parse_holes(bad)


@pytest.mark.parametrize("name", HOLED_SENSORS)
def test_the_noise_is_the_same_whatever_the_holes(name):
    depth, cam = scene_depth()
    own = simulate(name, depth, cam, seed=3, level=1.0)
    none = simulate(name, depth, cam, seed=3, level=1.0, holes=parse_holes("none"))
    dropped = simulate(name, depth, cam, seed=3, level=1.0, holes=parse_holes("random:0.1"))
    assert (none > 0).all()  # no hole at all, edges included
    assert not np.array_equal(none, depth)  # but noisy
    both = (own > 0) & (dropped > 0)
    np.testing.assert_array_equal(own[both], none[both])
    np.testing.assert_array_equal(dropped[both], none[both])
    # the physical holes are the edges of the box: about 4 x 2 x 48 of 96 x 96 pixels
    edges = simulate(name, depth, cam, seed=3, level=0.0, holes=parse_holes("physical"))
    assert 0.03 < np.mean(edges == 0) < 0.05


def test_a_given_dropout_rate_holds_at_any_noise_level():
    depth, cam = scene_depth()
    for i, level in enumerate((0.0, 1.0, 2.0)):
        measured = simulate("kinect", depth, cam, seed=[0, i], level=level,
                            holes=parse_holes("random:0.1"))
        # 9216 pixels at p = 0.1: the share is within 4 standard deviations (0.0125)
        assert abs(np.mean(measured == 0) - 0.1) < 0.0125
    exact = simulate("kinect", depth, cam, seed=0, level=0.0, holes=parse_holes("random:0.1"))
    kept = exact > 0
    np.testing.assert_array_equal(exact[kept], depth[kept])  # level 0: holes alone


@pytest.mark.parametrize("name", ["exact", "mono"])
def test_sensors_that_make_no_holes_refuse_a_spec(name):
    depth, cam = scene_depth(32)
    simulate(name, depth, cam, seed=0)  # their own (none) is fine
    with pytest.raises(ValueError, match=f"the {name} sensor makes no holes"):
        simulate(name, depth, cam, seed=0, holes=parse_holes("random:0.05"))
