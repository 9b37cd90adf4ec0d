"""Frame sizes: ``WxH`` parsing and its refusals, and non-square synthetic cameras."""

import numpy as np
import pytest

from vbgs.data.scene import parse_size, size_pixels, size_text
from vbgs.data.synthetic import ROOM_FOV_X, make_scene
from vbgs.render.camera import project, unproject


def test_parse_size_reads_numbers_and_pairs():
    assert parse_size("640x480") == (640, 480) == parse_size("640X480")
    assert parse_size([640, 480]) == (640, 480) == parse_size((640, 480))
    assert parse_size("128") == 128 == parse_size(128)  # one number stays a number
    assert size_pixels("640x480") == 307200 and size_pixels(128) == 16384
    assert size_text((48, 32)) == "48x32" and size_text(64) == "64"


@pytest.mark.parametrize("bad, says", [("640x", "not a size"), ("0x480", "at least 1"),
                                       ("x", "not a size"), ("1x2x3", "not a size"),
                                       (0, "at least 1"), ("abc", "not a size"),
                                       ([1, 2, 3], "two integers"), (1.5, "not a size"),
                                       (True, "not a size")])
def test_parse_size_refuses_bad_values(bad, says):
    with pytest.raises(ValueError, match=says):
        parse_size(bad)


def test_non_square_room_camera_and_depth_agree():
    scene = make_scene("room", size=(48, 32), n_train=2, n_test=1, n_val=0)
    for f in scene.train + scene.test:
        cam = f.camera
        assert (cam.width, cam.height) == (48, 32) and f.depth.shape == (32, 48)
        assert f.rgb.shape == (32, 48, 3)
        # the field of view is horizontal: fx from the width, square pixels
        assert cam.fx == pytest.approx(24.0 / np.tan(0.5 * ROOM_FOV_X)) and cam.fy == cam.fx
        assert (cam.cx, cam.cy) == (24.0, 16.0)
        xyz, _ = unproject(cam, f.rgb, f.depth)
        assert len(xyz) == 48 * 32  # the room is closed: every pixel has depth
        uv, z = project(cam, xyz)
        rows, cols = np.nonzero(f.depth > 0)
        np.testing.assert_allclose(uv, np.stack([cols + 0.5, rows + 0.5], -1), atol=2e-3)
        np.testing.assert_allclose(z, f.depth[rows, cols], rtol=1e-5)
