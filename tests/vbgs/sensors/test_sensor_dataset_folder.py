"""A scene whose training depth a sensor corrupted is written as a Blender-layout
folder and read back with the same depth, to the 16-bit PNG's 1 mm, holes still 0."""

import numpy as np
import pytest

from vbgs.data.blender import load_blender, write_blender
from vbgs.data.synthetic import object_scene
from vbgs.sensors import simulate

HALF_MM = 0.0005 + 1e-6  # the PNG stores round(depth * 1000); float32 rounding on top


@pytest.mark.parametrize("name", ["kinect", "mono"])
def test_corrupted_training_depth_round_trips(name, tmp_path):
    scene = object_scene(size=32, n_train=3, n_test=1, n_val=1)
    train = [f._replace(depth=simulate(name, f.depth, f.camera, seed=[0, i]))
             for i, f in enumerate(scene.train)]
    corrupted = scene._replace(train=train)
    back = load_blender(write_blender(corrupted, tmp_path / name))
    assert (len(back.train), len(back.test), len(back.val)) == (3, 1, 1)
    for written, read in zip(corrupted.train, back.train, strict=True):
        holes = written.depth == 0
        np.testing.assert_array_equal(read.depth == 0, holes)
        assert np.abs(read.depth - written.depth).max() <= HALF_MM
        if name == "kinect":
            assert 0.1 < holes.mean() < 0.9 and (read.depth[holes] == 0).all()
        else:
            assert not holes.any()  # mono: depth on every pixel, the background's too
    for split in ("test", "val"):  # the held-out views keep their exact depth
        exact, read = getattr(scene, split)[0], getattr(back, split)[0]
        np.testing.assert_array_equal(read.depth == 0, exact.depth == 0)
        assert np.abs(read.depth - exact.depth).max() <= HALF_MM


def test_depth_beyond_a_16_bit_png_is_written_as_npy(tmp_path):
    scene = object_scene(size=16, n_train=2, n_test=1, n_val=1)
    far = scene._replace(train=[scene.train[0]._replace(depth=scene.train[0].depth * 20)]
                         + scene.train[1:])  # up to ~90 units: beyond 65.535 m in mm
    with pytest.raises(ValueError, match="does not fit a 16-bit PNG"):
        write_blender(far, tmp_path / "png")
    back = load_blender(write_blender(far, tmp_path / "auto", depth="auto"))
    for written, read in zip(far.train + far.test, back.train + back.test, strict=True):
        np.testing.assert_array_equal(read.depth, written.depth)  # float32: exact
    assert not list((tmp_path / "auto").rglob("*_depth.png"))
    again = write_blender(scene, tmp_path / "auto", depth="auto")  # fits: PNGs
    assert list((tmp_path / "auto").rglob("*_depth.png"))
    write_blender(far, again, depth="npy")  # a stale PNG the loader would prefer is removed
    assert not list((tmp_path / "auto").rglob("*_depth.png"))
    with pytest.raises(ValueError, match="depth files 'tiff'"):
        write_blender(scene, tmp_path / "x", depth="tiff")
