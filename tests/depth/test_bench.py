"""The depth benchmark: the adapter computes what a bare onnxruntime session computes."""

import numpy as np
import onnxruntime as ort
import pytest

from depth.bench import bench_adapter, bench_model_bytes
from depth.onnx_depth import OnnxDepth
from depth.presets import IMAGENET_MEAN, IMAGENET_STD


def test_adapter_output_equals_a_raw_session_on_the_same_frames():
    model = bench_model_bytes(seed=3)
    frames = np.random.default_rng(0).random((5, 24, 20, 3), dtype=np.float32)
    adapter = OnnxDepth(model, kind="relative", mean=IMAGENET_MEAN, std=IMAGENET_STD,
                        batch_size=2)
    # the raw session's input made by hand: ImageNet normalisation, NHWC -> NCHW
    x = (frames - np.float32(IMAGENET_MEAN)) / np.float32(IMAGENET_STD)
    x = np.ascontiguousarray(x.transpose(0, 3, 1, 2), np.float32)  # [5, 3, 24, 20]
    session = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
    raw = session.run(["y"], {"x": x})[0][:, 0]  # [5, 24, 20]
    out = adapter.predict(frames)
    assert out.shape == (5, 24, 20) and out.dtype == np.float32
    assert np.abs(raw).max() > 0.1  # the model does something
    np.testing.assert_allclose(out, raw, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(adapter.predict(frames[2]), raw[2], rtol=1e-5, atol=1e-5)


def test_bench_adapter_times_the_same_computation():
    result = bench_adapter(size=32, n_frames=4, batch_size=2, repeats=1)
    assert (result["size"], result["n_frames"], result["batch_size"]) == (32, 4, 2)
    assert result["max_abs_diff"] < 1e-5  # adapter and session outputs agree
    assert result["adapter_over_session"] == pytest.approx(
        result["session_fps"] / result["adapter_fps"])
