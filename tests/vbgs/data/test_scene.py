import numpy as np
import pytest

from vbgs.data.scene import (
    Frame,
    Scene,
    bounds_from_frames,
    hold_out,
    resize_frame,
    select,
    target_size,
    validate_frame,
    validate_scene,
)
from vbgs.render.camera import Camera, look_at, project


def _frame(h=6, w=8):
    cam = Camera(7.0, 6.0, 4.0, 3.0, w, h, look_at([0.0, -3.0, 1.0], [0.0, 0.0, 0.0]))
    rgb = np.random.default_rng(0).uniform(0, 1, (h, w, 3)).astype(np.float32)
    return Frame(rgb, np.full((h, w), 2.0, np.float32), cam)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda f: f._replace(rgb=f.rgb[:, :-1]), "rgb has shape"),
        (lambda f: f._replace(depth=f.depth.T), "depth has shape"),
        (lambda f: f._replace(rgb=f.rgb.astype(np.float64)), "dtype float64"),
        (lambda f: f._replace(rgb=np.where(f.rgb > 0.5, np.nan, f.rgb).astype(np.float32)), "NaN"),
        (lambda f: f._replace(rgb=f.rgb * 255), "divide 8-bit"),
        (lambda f: f._replace(depth=np.full_like(f.depth, np.nan)), "48 NaN"),
        (lambda f: f._replace(camera=f.camera._replace(fx=0.0)), "focal"),
    ],
)
def test_validate_frame_names_the_problem(change, message):
    assert validate_frame(_frame()) is not None
    with pytest.raises(ValueError, match=message) as err:
        validate_frame(change(_frame()), "train frame 3")
    assert "train frame 3" in str(err.value)


def test_validate_scene():
    f = _frame()
    lo, hi = np.zeros(3), np.ones(3)
    assert validate_scene(Scene("s", [f], [], (lo, hi))).name == "s"
    with pytest.raises(ValueError, match="no training frames"):
        validate_scene(Scene("s", [], [f], (lo, hi)))
    with pytest.raises(ValueError, match="test frame 0"):
        validate_scene(Scene("s", [f], [f._replace(depth=-f.depth)], (lo, hi)))


def test_resize_scales_intrinsics_exactly():
    f = _frame(12, 16)
    small = resize_frame(f, 8)  # longer side 8 -> 8 x 6
    assert target_size(16, 12, 8) == (8, 6) and target_size(16, 12, (4, 5)) == (4, 5)
    assert small.rgb.shape == (6, 8, 3) and small.depth.shape == (6, 8)
    assert small.rgb.dtype == np.float32 and small.depth.dtype == np.float32
    points = np.array([[0.3, 0.1, 0.2], [-0.5, 0.4, 0.0]])
    uv_big, z_big = project(f.camera, points)
    uv_small, z_small = project(small.camera, points)
    np.testing.assert_allclose(uv_small, uv_big * 0.5)
    np.testing.assert_allclose(z_small, z_big)
    assert resize_frame(f, None) is f
    np.testing.assert_allclose(small.rgb.mean(), f.rgb.mean(), atol=0.02)


def test_select_and_hold_out():
    assert select(10, 3) == [0, 3, 6, 9] and select(10, 2, max_frames=2) == [0, 2]
    with pytest.raises(ValueError, match="stride"):
        select(10, 0)
    train, test = hold_out(list(range(10)), 4)
    assert test == [2, 6] and train == [0, 1, 3, 4, 5, 7, 8, 9]
    assert hold_out([1, 2], None) == ([1, 2], [])


def test_bounds_from_frames():
    f = _frame()
    lo, hi = bounds_from_frames([f])
    assert lo.dtype == np.float32 and np.all(lo < hi)
    centre = f.camera.pose[:3, 2] * 2.0 + f.camera.position  # the optical axis at depth 2
    assert np.all(lo <= centre + 1e-5) and np.all(centre - 1e-5 <= hi)
    blind = f._replace(depth=np.zeros_like(f.depth))
    lo, hi = bounds_from_frames([blind])  # no depth: the camera centres
    np.testing.assert_allclose(lo, f.camera.position)
