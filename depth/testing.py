"""Small ONNX graphs built with ``onnx.helper`` for testing the depth adapter.

Needs the ``onnx`` package (the ``test`` extra); this module is imported only by the
tests and by the RGB-only study (``python -m experiments.run depth-study``).

Every builder returns an ``onnx.ModelProto``; pass ``model.SerializeToString()`` to
``depth.OnnxDepth`` or ``onnx.save(model, path)`` for the CLI.

- :func:`channel_sum_model`: ``depth = sum_c w_c x_c + bias`` per pixel (exact, so
  layout, resizing, normalisation and batching can be checked by hand);
- broken models the adapter must refuse;
- :func:`lookup_model`: returns the stored output of the stored RGB frame nearest to
  the input; :func:`depth_lookup_model` stores a distorted true depth, for RGB-only
  end-to-end runs on synthetic scenes.
"""

from __future__ import annotations

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OPSET = 17
FLOAT = TensorProto.FLOAT


def _const(name: str, value) -> onnx.TensorProto:
    return numpy_helper.from_array(np.asarray(value), name)


def _model(nodes, inputs, outputs, initializers=(), name="test") -> onnx.ModelProto:
    graph = helper.make_graph(nodes, name, inputs, outputs, list(initializers))
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)])
    model.ir_version = 8  # readable by every onnxruntime >= 1.17
    onnx.checker.check_model(model)
    return model


def _image_shape(layout: str, size, batch) -> list:
    n = batch if batch is not None else "N"
    h, w = size if size is not None else ("H", "W")
    return [n, 3, h, w] if layout == "NCHW" else [n, h, w, 3]


def channel_sum_model(
    weights=(0.5, 0.3, 0.2),
    bias: float = 0.1,
    *,
    layout: str = "NCHW",
    size: tuple[int, int] | None = None,
    batch: int | None = None,
    output: str = "NHW",
    pool: int = 1,
    half_input: bool = False,
    symbolic_channels: bool = False,
) -> onnx.ModelProto:
    """``y[n, i, j] = sum_c weights[c] * x[n, c, i, j] + bias`` (NCHW or NHWC input).

    ``size``/``batch`` fix the input's (H, W)/N (None: symbolic); ``output`` is the
    output layout "NHW", "N1HW" or "NHW1"; ``pool > 1`` average-pools the output by
    that factor (a model whose depth map is smaller than its input; NCHW only).
    ``half_input`` declares a float16 input (cast to float inside);
    ``symbolic_channels`` leaves the input and output channel axes unnamed sizes.
    """
    c_axis = 1 if layout == "NCHW" else 3
    w_shape = [1, 3, 1, 1] if layout == "NCHW" else [1, 1, 1, 3]
    inits = [
        _const("w", np.asarray(weights, np.float32).reshape(w_shape)),
        _const("b", np.float32(bias)),
        _const("c_axis", np.array([c_axis], np.int64)),
    ]
    nodes = [helper.make_node("Cast", ["x"], ["x32"], to=FLOAT)] if half_input else []
    nodes += [
        helper.make_node("Mul", ["x32" if half_input else "x", "w"], ["xw"]),
        helper.make_node("ReduceSum", ["xw", "c_axis"], ["s"], keepdims=1),
        helper.make_node("Add", ["s", "b"], ["y4"]),  # [N,1,H,W] or [N,H,W,1]
    ]
    last = "y4"
    if pool > 1:
        assert layout == "NCHW", "pool needs NCHW"
        nodes.append(helper.make_node(
            "AveragePool", ["y4"], ["y4p"], kernel_shape=[pool, pool], strides=[pool, pool]
        ))
        last = "y4p"
    native = "N1HW" if layout == "NCHW" else "NHW1"
    if output == "NHW":
        nodes.append(helper.make_node("Squeeze", [last, "c_axis"], ["y"]))
    elif output == native:
        nodes.append(helper.make_node("Identity", [last], ["y"]))
    else:
        perm = [0, 2, 3, 1] if layout == "NCHW" else [0, 3, 1, 2]
        nodes.append(helper.make_node("Transpose", [last], ["y"], perm=perm))
    n = batch if batch is not None else "N"
    one = "C1" if symbolic_channels else 1
    out_shape = {"NHW": [n, "Ho", "Wo"], "N1HW": [n, one, "Ho", "Wo"], "NHW1": [n, "Ho", "Wo", one]}
    in_shape = _image_shape(layout, size, batch)
    if symbolic_channels:
        in_shape[c_axis] = "C"
    x_type = TensorProto.FLOAT16 if half_input else FLOAT
    x = helper.make_tensor_value_info("x", x_type, in_shape)
    y = helper.make_tensor_value_info("y", FLOAT, out_shape[output])
    return _model(nodes, [x], [y], inits, "channel_sum")


def rank3_input_model() -> onnx.ModelProto:
    """Input ``[3, H, W]`` (no batch axis): refused."""
    x = helper.make_tensor_value_info("x", FLOAT, [3, "H", "W"])
    y = helper.make_tensor_value_info("y", FLOAT, [3, "H", "W"])
    return _model([helper.make_node("Identity", ["x"], ["y"])], [x], [y])


def no_input_model() -> onnx.ModelProto:
    """A graph that only outputs a constant: refused."""
    y = helper.make_tensor_value_info("y", FLOAT, [1, 4, 4])
    value = _const("v", np.ones((1, 4, 4), np.float32))
    node = helper.make_node("Constant", [], ["y"], value=value)
    return _model([node], [], [y])


def int_output_model() -> onnx.ModelProto:
    """Output cast to int64: refused."""
    x = helper.make_tensor_value_info("x", FLOAT, ["N", 3, "H", "W"])
    y = helper.make_tensor_value_info("y", TensorProto.INT64, ["N", "H", "W"])
    nodes = [
        helper.make_node("ReduceSum", ["x", "ax"], ["s"], keepdims=0),
        helper.make_node("Cast", ["s"], ["y"], to=TensorProto.INT64),
    ]
    return _model(nodes, [x], [y], [_const("ax", np.array([1], np.int64))])


def rank1_output_model() -> onnx.ModelProto:
    """Output ``[N]`` (one number per image): refused."""
    x = helper.make_tensor_value_info("x", FLOAT, ["N", 3, "H", "W"])
    y = helper.make_tensor_value_info("y", FLOAT, ["N"])
    node = helper.make_node("ReduceSum", ["x", "ax"], ["y"], keepdims=0)
    return _model([node], [x], [y], [_const("ax", np.array([1, 2, 3], np.int64))])


def int_input_model() -> onnx.ModelProto:
    """Only an int64 image input: refused (no float input)."""
    x = helper.make_tensor_value_info("x", TensorProto.INT64, ["N", 3, "H", "W"])
    y = helper.make_tensor_value_info("y", FLOAT, ["N", "H", "W"])
    nodes = [
        helper.make_node("Cast", ["x"], ["xf"], to=FLOAT),
        helper.make_node("ReduceSum", ["xf", "ax"], ["y"], keepdims=0),
    ]
    return _model(nodes, [x], [y], [_const("ax", np.array([1], np.int64))])


def four_channel_model() -> onnx.ModelProto:
    """Input ``[N, 4, H, 5]``: no 3-channel axis, refused."""
    x = helper.make_tensor_value_info("x", FLOAT, ["N", 4, "H", 5])
    y = helper.make_tensor_value_info("y", FLOAT, ["N", "H", 5])
    node = helper.make_node("ReduceSum", ["x", "ax"], ["y"], keepdims=0)
    return _model([node], [x], [y], [_const("ax", np.array([1], np.int64))])


def two_image_model() -> onnx.ModelProto:
    """Two float image inputs ``a``, ``b``; output ``sum_c (a + b)``."""
    a = helper.make_tensor_value_info("a", FLOAT, ["N", 3, "H", "W"])
    b = helper.make_tensor_value_info("b", FLOAT, ["N", 3, "H", "W"])
    y = helper.make_tensor_value_info("y", FLOAT, ["N", "H", "W"])
    nodes = [
        helper.make_node("Add", ["a", "b"], ["ab"]),
        helper.make_node("ReduceSum", ["ab", "ax"], ["y"], keepdims=0),
    ]
    return _model(nodes, [a, b], [y], [_const("ax", np.array([1], np.int64))])


def distorted_depth(
    depth_frames: np.ndarray, scale: float, shift: float, noise_std: float, seed: int,
    space: str = "inverse",
) -> np.ndarray:
    """The stored prediction ``[m, h, w]`` float32 of :func:`depth_lookup_model`.

    ``space="inverse"``: ``p = scale / depth + shift + e`` (relative disparity, as
    Depth Anything/MiDaS give; recovered by ``scale-shift-inverse`` alignment);
    ``space="depth"``: ``p = scale * depth + shift + e`` (affine-invariant depth).
    ``e ~ N(0, noise_std^2)`` drawn once from ``seed``; ``p = 0`` where depth <= 0.
    """
    depth = np.asarray(depth_frames, np.float64)
    valid = np.isfinite(depth) & (depth > 0)
    safe = np.where(valid, depth, 1.0)
    clean = scale / safe + shift if space == "inverse" else scale * safe + shift
    noise = np.random.default_rng(seed).normal(0.0, noise_std, depth.shape)
    return np.where(valid, clean + noise, 0.0).astype(np.float32)


def depth_lookup_model(
    rgb_frames: np.ndarray,
    depth_frames: np.ndarray,
    scale: float,
    shift: float,
    noise_std: float = 0.0,
    seed: int = 0,
    *,
    space: str = "inverse",
) -> onnx.ModelProto:
    """A "depth network" that has memorised ``m`` RGB-D frames: :func:`lookup_model` of
    their distorted depth (:func:`distorted_depth`)."""
    return lookup_model(rgb_frames, distorted_depth(depth_frames, scale, shift, noise_std,
                                                    seed, space))


def lookup_model(rgb_frames: np.ndarray, table: np.ndarray) -> onnx.ModelProto:
    """A "depth network" that has memorised ``m`` frames and their outputs.

    Input ``x [N, 3, h, w]`` (NCHW, RGB in [0, 1], no normalisation; h, w fixed).
    For each image it finds the stored frame nearest in L2,
    ``k = argmin_j sum_{c,i,j'} (x - rgb_j)^2`` (ReduceSum, ArgMin), and outputs
    ``table[k]`` (Gather); ``rgb_frames [m, h, w, 3]``, ``table [m, h, w]``.
    """
    rgb = np.asarray(rgb_frames)
    if not np.issubdtype(rgb.dtype, np.floating) or rgb.min() < 0.0 or rgb.max() > 1.0:
        raise ValueError("rgb_frames must be float [m, h, w, 3] in [0, 1]")
    rgb = rgb.astype(np.float32)
    _, h, w, _ = rgb.shape
    table = np.asarray(table, np.float32)
    if table.shape != rgb.shape[:3]:
        raise ValueError(f"table {table.shape} must be [m, h, w] = {rgb.shape[:3]}")
    inits = [
        _const("stored_rgb", np.ascontiguousarray(rgb.transpose(0, 3, 1, 2))),  # [m,3,h,w]
        _const("table", table),  # [m,h,w]
        _const("ax1", np.array([1], np.int64)),
        _const("ax234", np.array([2, 3, 4], np.int64)),
    ]
    nodes = [
        helper.make_node("Unsqueeze", ["x", "ax1"], ["xu"]),  # [N,1,3,h,w]
        helper.make_node("Sub", ["xu", "stored_rgb"], ["diff"]),  # [N,m,3,h,w]
        helper.make_node("Mul", ["diff", "diff"], ["sq"]),
        helper.make_node("ReduceSum", ["sq", "ax234"], ["dist"], keepdims=0),  # [N,m]
        helper.make_node("ArgMin", ["dist"], ["idx"], axis=1, keepdims=0),  # [N]
        helper.make_node("Gather", ["table", "idx"], ["y"], axis=0),  # [N,h,w]
    ]
    x = helper.make_tensor_value_info("x", FLOAT, ["N", 3, h, w])
    y = helper.make_tensor_value_info("y", FLOAT, ["N", h, w])
    return _model(nodes, [x], [y], inits, "depth_lookup")
