"""Throughput of :class:`depth.OnnxDepth` against bare ``session.run``.

``python -m depth.bench [size] [n_frames]`` prints the dictionary of
:func:`bench_adapter`. Needs ``onnx`` (a test extra) to build its small model.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from depth.onnx_depth import OnnxDepth
from depth.presets import IMAGENET_MEAN, IMAGENET_STD

BENCH_CHANNELS = 16  # hidden width of the small convolutional test model
BENCH_OPSET = 17
BENCH_IR_VERSION = 8
BENCH_BATCH = 8
BENCH_REPEATS = 5


def bench_model_bytes(seed: int = 0, channels: int = BENCH_CHANNELS) -> bytes:
    """A small depth-like CNN, serialized: conv3x3(3->c) ReLU conv3x3(c->c) ReLU
    conv1x1(c->1) -> [N, 1, H, W], dynamic N, H, W; seeded random weights."""
    try:
        from onnx import TensorProto, helper, numpy_helper
    except ImportError as err:
        raise ImportError(
            "depth.bench builds its model with the 'onnx' package: pip install onnx "
            "(or the project's test extra: pip install -e '.[test]')"
        ) from err
    rng = np.random.default_rng(seed)

    def weight(name, shape):
        fan_in = int(np.prod(shape[1:]))
        w = rng.normal(0.0, 1.0 / np.sqrt(fan_in), shape).astype(np.float32)
        return numpy_helper.from_array(w, name)

    inits = [weight("w1", (channels, 3, 3, 3)), weight("w2", (channels, channels, 3, 3)),
             weight("w3", (1, channels, 1, 1))]
    nodes = [
        helper.make_node("Conv", ["x", "w1"], ["h1"], pads=[1, 1, 1, 1]),
        helper.make_node("Relu", ["h1"], ["a1"]),
        helper.make_node("Conv", ["a1", "w2"], ["h2"], pads=[1, 1, 1, 1]),
        helper.make_node("Relu", ["h2"], ["a2"]),
        helper.make_node("Conv", ["a2", "w3"], ["y"]),
    ]
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, ["N", 3, "H", "W"])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, ["N", 1, "H", "W"])
    graph = helper.make_graph(nodes, "bench_cnn", [x], [y], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", BENCH_OPSET)])
    model.ir_version = BENCH_IR_VERSION
    return model.SerializeToString()


def _best_seconds(fns, repeats: int) -> list[float]:
    """Best wall time of each function; runs are interleaved so that load from other
    processes hits all of them alike. One warm-up run each first."""
    for fn in fns:
        fn()
    best = [float("inf")] * len(fns)
    for _ in range(repeats):
        for i, fn in enumerate(fns):
            start = time.perf_counter()
            fn()
            best[i] = min(best[i], time.perf_counter() - start)
    return best


def bench_adapter(size: int = 256, n_frames: int = 32, *, batch_size: int = BENCH_BATCH,
                  repeats: int = BENCH_REPEATS, seed: int = 0) -> dict:
    """Frames per second of ``OnnxDepth.predict`` vs ``session.run`` on prepared input,
    and ``max_abs_diff``: the largest difference between their outputs (they must agree).

    Both use the same model, CPU provider and batch size. The adapter's time includes
    frame checks, ImageNet normalisation, NCHW transpose and output squeeze; the
    model input equals the frame size, so no resizing happens. Best of ``repeats``.
    """
    import onnxruntime as ort

    model = bench_model_bytes(seed)
    frames = np.random.default_rng(seed).random((n_frames, size, size, 3), dtype=np.float32)
    adapter = OnnxDepth(model, kind="relative", mean=IMAGENET_MEAN, std=IMAGENET_STD,
                        batch_size=batch_size)
    session = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
    prepared = [adapter.preprocess(frames[i:i + batch_size])
                for i in range(0, n_frames, batch_size)]

    def raw():
        for x in prepared:
            session.run(["y"], {"x": x})

    adapter_s, session_s = _best_seconds([lambda: adapter.predict(frames), raw], repeats)
    session_out = np.concatenate([session.run(["y"], {"x": x})[0][:, 0] for x in prepared])
    return {
        "size": size, "n_frames": n_frames, "batch_size": batch_size,
        "max_abs_diff": float(np.abs(adapter.predict(frames) - session_out).max()),
        "adapter_fps": n_frames / adapter_s, "session_fps": n_frames / session_s,
        "adapter_over_session": adapter_s / session_s,
        "overhead_ms_per_frame": 1000.0 * (adapter_s - session_s) / n_frames,
    }


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:3]]
    for key, value in bench_adapter(*args).items():
        print(f"{key}: {value:.4g}" if isinstance(value, float) else f"{key}: {value}")
