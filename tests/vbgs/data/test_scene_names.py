"""vbgs.data.scene_names: the names a command's help gives are the scenes that load."""

from vbgs.data import scene_names
from vbgs.data.stereo import REAL_SCENES
from vbgs.data.synthetic import PRIMITIVES, SCENES


def test_the_names_are_the_registries_keys():
    assert tuple(SCENES) == scene_names.SYNTHETIC
    assert tuple(PRIMITIVES) == scene_names.SYNTHETIC
    assert tuple(REAL_SCENES) == scene_names.REAL
