"""A depth network's far field is cut out of the surface; a room's far walls are not."""

import numpy as np

from vbgs.data.synthetic import make_scene
from vbgs.sensors import SENSORS, simulate
from vbgs.sensors.far_field import far_field


def _object_frames(size=48, n=4):
    return make_scene("object", size=size, n_train=n, n_test=1, seed=0, n_val=0).train


def test_mono_fill_is_far_field_and_little_surface_is():
    for i, frame in enumerate(_object_frames()):
        mono = simulate("mono", frame.depth, frame.camera, seed=[0, 7, i])
        far = far_field(mono)
        empty = frame.depth == 0
        assert empty.any() and np.all(far[empty])  # every background pixel caught
        # what else is cut: depth bled across the silhouette (about 3 % at 64 px)
        assert np.count_nonzero(far & ~empty) < 0.08 * far.size


def test_no_gap_or_no_plateau_means_no_far_field():
    v, u = np.mgrid[0:40, 0:40]
    ramp = 1.0 + 0.1 * v  # a floor running away: depths 1 to 4.9, no gap
    assert not far_field(ramp).any()
    room = ramp + 1.0  # far walls at 2 to 5.9 ...
    room[15:25, 15:25] = 0.9  # ... behind a near stool: a gap of 2.2, but no plateau
    assert not far_field(room).any()
    sky = ramp.copy()
    sky[:10] = 9.0  # a flat plateau beyond a gap: the sky
    assert np.array_equal(far_field(sky), sky == 9.0)


def test_surface_of_each_sensor():
    frame = _object_frames(n=1)[0]
    exact = SENSORS["exact"].surface(frame.depth, frame.camera)
    assert np.array_equal(exact, frame.depth)
    mono = simulate("mono", frame.depth, frame.camera, seed=[0, 7, 0])
    kept = SENSORS["mono"].surface(mono, frame.camera)
    assert np.all(kept[frame.depth == 0] == 0)  # no shell
    assert np.array_equal(kept[kept > 0], mono[kept > 0])  # what is kept is unchanged
    # the edges go too (depth bled across them); most of the surface stays
    assert 0.5 < np.count_nonzero(kept) / np.count_nonzero(frame.depth) < 0.95
