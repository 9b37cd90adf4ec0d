import numpy as np
import pytest

from depth.preprocess import as_frames, input_hw, normalise, resize, to_model_input
from depth.presets import IMAGENET_MEAN, IMAGENET_STD


def test_resize_same_size_is_identity():
    a = np.random.default_rng(0).random((2, 7, 9, 3), dtype=np.float32)
    assert resize(a, (7, 9), (1, 2)) is a


@pytest.mark.parametrize("hw", [(5, 4), (23, 31), (40, 13)])
def test_resize_keeps_constants(hw):
    a = np.full((1, 12, 16, 3), 0.37, np.float32)
    np.testing.assert_allclose(resize(a, hw, (1, 2)), 0.37, rtol=1e-6)


@pytest.mark.parametrize("n_out", [24, 17, 6, 4])  # enlarge x2, x1.4; shrink x2, x3 (symmetric)
def test_resize_linear_ramp_interior_is_exact(n_out):
    n_in = 12
    ramp = np.arange(n_in, dtype=np.float32)[:, None]  # [h, 1]
    out = resize(ramp, (n_out, 1), (0, 1))[:, 0]
    centres = (np.arange(n_out) + 0.5) * n_in / n_out - 0.5
    radius = max(1.0, n_in / n_out)
    interior = (centres - radius >= 0) & (centres + radius <= n_in - 1)
    assert interior.any()
    np.testing.assert_allclose(out[interior], centres[interior], atol=1e-5)


def test_input_hw_rules():
    assert input_hw((480, 640), 518, True, 14) == (518, 686)  # 690.7 -> 49 * 14
    assert input_hw((480, 640), 384, False, 32) == (384, 384)
    assert input_hw((480, 640), (100, 200), True, 1) == (100, 200)
    assert input_hw((50, 70), None, True, 32) == (64, 64)
    assert input_hw((480, 640), 518, True, 14, fixed_hw=(518, None)) == (518, 686)
    assert input_hw((480, 640), 518, True, 14, fixed_hw=(256, 320)) == (256, 320)


def test_as_frames_uint8_single_and_list():
    img = np.full((4, 5, 3), 51, np.uint8)
    batch, single = as_frames(img)
    assert single and batch.shape == (1, 4, 5, 3) and batch.dtype == np.float32
    np.testing.assert_allclose(batch, 0.2, rtol=1e-6)
    batch, single = as_frames([img, img])
    assert not single and batch.shape == (2, 4, 5, 3)


@pytest.mark.parametrize("frames, message", [
    (np.zeros((4, 5)), "greyscale"),
    (np.zeros((4, 5, 4)), "drop alpha"),
    (np.zeros((2, 4, 5, 2)), "RGB image"),
    (np.zeros((4, 5, 3), np.int32), "uint8 or float"),
    (np.full((4, 5, 3), 200.0), "divide 0-255"),
    ([np.zeros((4, 5, 3)), np.zeros((5, 5, 3))], "share a size"),
    ([], "no frames"),
    (np.zeros((3, 4, 5, 6, 3)), "[n, h, w, 3]"),
])
def test_as_frames_refuses_bad_frames(frames, message):
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        as_frames(frames)


def test_as_frames_refuses_nan_and_names_the_frame():
    frames = np.zeros((3, 4, 5, 3), np.float32)
    frames[2, 1, 1, 0] = np.nan
    with pytest.raises(ValueError, match="frame 2 contains NaN"):
        as_frames(frames)


@pytest.mark.parametrize("layout", ["NCHW", "NHWC"])
def test_fast_model_input_matches_reference_formula(layout):
    rgb = np.random.default_rng(1).random((2, 6, 7, 3), dtype=np.float32)
    want = normalise(rgb, IMAGENET_MEAN, IMAGENET_STD)
    if layout == "NCHW":
        want = want.transpose(0, 3, 1, 2)
    got = to_model_input(rgb, IMAGENET_MEAN, IMAGENET_STD, layout)
    assert got.flags.c_contiguous and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
    assert rgb.min() >= 0  # input untouched
