import numpy as np
import pytest

from depth import PRESETS, OnnxDepth
from depth import testing as om
from depth.model_io import ModelIO, to_nhw
from depth.preprocess import resize
from depth.presets import IMAGENET_MEAN, IMAGENET_STD

W = np.array([0.5, 0.3, 0.2], np.float32)
B = 0.1


def _frames(n=3, h=20, w=30, seed=0):
    return np.random.default_rng(seed).random((n, h, w, 3), dtype=np.float32)


def _channel_sum(frames, mean=(0, 0, 0), std=(1, 1, 1)):
    x = (frames - np.asarray(mean, np.float32)) / np.asarray(std, np.float32)
    return x @ W + B


@pytest.mark.parametrize("layout", ["NCHW", "NHWC"])
@pytest.mark.parametrize("output", ["NHW", "N1HW", "NHW1"])
@pytest.mark.parametrize("size", [None, (20, 30)])
def test_layouts_and_output_shapes_give_the_exact_function(layout, output, size):
    model = OnnxDepth(om.channel_sum_model(W, B, layout=layout, output=output, size=size)
                      .SerializeToString())
    assert model.io.layout == layout and model.io.fixed_hw == (size or (None, None))
    frames = _frames()
    pred = model.predict(frames)
    assert pred.shape == (3, 20, 30) and pred.dtype == np.float32
    np.testing.assert_allclose(pred, _channel_sum(frames), atol=1e-6)


def test_constant_image_gives_constant_depth_after_normalisation():
    model = OnnxDepth(om.channel_sum_model(W, B).SerializeToString(), preset="depth-anything")
    assert model.kind == "inverse" and model.input_hw((20, 30)) == (518, 784)
    rgb = np.array([0.2, 0.6, 0.9], np.float32)
    by_hand = sum(W[c] * (rgb[c] - IMAGENET_MEAN[c]) / IMAGENET_STD[c] for c in range(3)) + B
    pred = model.predict(np.broadcast_to(rgb, (20, 30, 3)).copy())
    assert pred.shape == (20, 30)
    np.testing.assert_allclose(pred, by_hand, rtol=1e-5)


def test_resizing_in_and_out_composes_exactly():
    """Channel sum is per-pixel linear, so predict = up(down(sum_c w_c x_c) + b)."""
    model = OnnxDepth(om.channel_sum_model(W, B).SerializeToString(), input_size=16,
                      keep_aspect=True, multiple_of=8)
    frames = _frames(2, 24, 40)
    assert model.input_hw((24, 40)) == (16, 24)
    small = resize(frames, (16, 24), (1, 2)) @ W + B
    want = resize(small, (24, 40), (1, 2))
    np.testing.assert_allclose(model.predict(frames), want, atol=1e-5)


def test_output_smaller_than_input_is_resized_to_frame_size():
    model = OnnxDepth(om.channel_sum_model(W, B, pool=2).SerializeToString())
    frames = np.full((2, 12, 18, 3), 0.5, np.float32)
    pred = model.predict(frames)
    assert pred.shape == (2, 12, 18)
    np.testing.assert_allclose(pred, 0.5 * W.sum() + B, rtol=1e-6)


@pytest.mark.parametrize("batch, batch_size", [(None, 2), (None, 1), (None, 8), (1, 4), (2, 4)])
def test_batched_equals_one_by_one(batch, batch_size):
    model = OnnxDepth(om.channel_sum_model(W, B, batch=batch).SerializeToString(),
                      batch_size=batch_size, input_size=12)
    frames = _frames(5, 18, 26)
    together = model.predict(frames)
    alone = np.stack([model.predict(f) for f in frames])
    np.testing.assert_array_equal(together, alone)
    assert model.batch_size == (batch or batch_size)


def test_uint8_frames_equal_float_frames():
    model = OnnxDepth(om.channel_sum_model(W, B).SerializeToString())
    img = (np.random.default_rng(3).random((9, 11, 3)) * 255).astype(np.uint8)
    np.testing.assert_allclose(model.predict(img), model.predict(img / np.float32(255)),
                               atol=1e-6)


def test_presets_are_documented_and_complete():
    assert {"depth-anything", "midas", "dpt", "metric"} <= set(PRESETS)
    assert PRESETS["depth-anything"].input_size == 518
    assert PRESETS["depth-anything"].multiple_of == 14
    assert PRESETS["midas"].multiple_of == 32 and PRESETS["dpt"].mean == (0.5, 0.5, 0.5)
    assert PRESETS["metric"].kind == "metric"


@pytest.mark.parametrize("builder, message", [
    (om.rank3_input_model, "has rank 3; expected a 4-D image batch"),
    (om.no_input_model, "has no inputs"),
    (om.int_output_model, "is not a float tensor; a depth model must return a float depth map"),
    (om.rank1_output_model, "has rank 1; expected a depth batch"),
    (om.int_input_model, "has no float input"),
    (om.four_channel_model, "has no 3-channel axis"),
    (om.two_image_model, "more than one float input .* input_name="),
])
def test_broken_models_are_refused_with_a_clear_message(builder, message):
    with pytest.raises(ValueError, match=message):
        OnnxDepth(builder().SerializeToString())


def test_second_image_input_needs_a_feed():
    model_bytes = om.two_image_model().SerializeToString()
    with pytest.raises(ValueError, match=r"needs inputs \['b'\].*extra_feeds"):
        OnnxDepth(model_bytes, input_name="a")
    b = np.full((1, 3, 6, 7), 1.0, np.float32)
    model = OnnxDepth(model_bytes, input_name="a", extra_feeds={"b": b}, batch_size=1)
    np.testing.assert_allclose(model.predict(np.zeros((6, 7, 3), np.float32)), 3.0)


def test_missing_or_garbage_model_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="ONNX depth model not found"):
        OnnxDepth(tmp_path / "nope.onnx")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="could not load the model"):
        OnnxDepth(bad)


def test_explicit_size_conflicting_with_fixed_graph_size_is_refused():
    model = om.channel_sum_model(W, B, size=(20, 30)).SerializeToString()
    with pytest.raises(ValueError, match="fixed input height 20"):
        OnnxDepth(model, input_size=(24, 30))


def test_unknown_provider_lists_the_available_ones():
    with pytest.raises(ValueError, match="not available here; available: .*CPUExecutionProvider"):
        OnnxDepth(om.channel_sum_model().SerializeToString(), providers="nosuchdevice")
    model = OnnxDepth(om.channel_sum_model().SerializeToString(), providers="cpu")
    assert model.providers == ["CPUExecutionProvider"]


def test_bad_frames_are_refused():
    model = OnnxDepth(om.channel_sum_model().SerializeToString())
    with pytest.raises(ValueError, match=r"RGB image \[h, w, 3\]"):
        model.predict(np.zeros((8, 8, 2), np.float32))
    frame = np.zeros((8, 8, 3), np.float32)
    frame[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        model.predict(frame)


def test_float16_input_is_fed_as_float16():
    model = OnnxDepth(om.channel_sum_model(W, B, half_input=True).SerializeToString())
    assert model.io.input_dtype == np.float16
    frames = _frames(2, 8, 10)
    np.testing.assert_allclose(model.predict(frames), _channel_sum(frames), atol=2e-3)


@pytest.mark.parametrize("output", ["N1HW", "NHW1"])
def test_symbolic_channel_axes_need_a_layout_and_resolve_at_run_time(output):
    model_bytes = om.channel_sum_model(W, B, output=output, symbolic_channels=True)
    model_bytes = model_bytes.SerializeToString()
    with pytest.raises(ValueError, match="cannot tell the channel axis.*layout="):
        OnnxDepth(model_bytes)
    model = OnnxDepth(model_bytes, layout="NCHW")
    frames = _frames(2, 8, 10)
    np.testing.assert_allclose(model.predict(frames), _channel_sum(frames), atol=1e-6)


def test_output_channel_axis_found_at_run_time_when_the_graph_does_not_say():
    io = ModelIO("x", np.float32, "NCHW", None, (None, None), "y", None)
    y = np.arange(12, dtype=np.float32).reshape(1, 3, 4)
    np.testing.assert_array_equal(to_nhw(y[:, None], io), y)
    np.testing.assert_array_equal(to_nhw(y[..., None], io), y)
    with pytest.raises(ValueError, match=r"returned shape \(1, 2, 3, 4\)"):
        to_nhw(np.zeros((1, 2, 3, 4)), io)
