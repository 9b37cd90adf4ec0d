"""Load an ONNX depth model with onnxruntime and work out its input/output layout.

Everything a user can get wrong about a model is refused here, once, at load time,
with a message naming the input or output and what was expected.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

FLOAT_TYPES = {
    "tensor(float)": np.float32,
    "tensor(float16)": np.float16,
    "tensor(double)": np.float64,
}
LAYOUTS = ("NCHW", "NHWC")
CHANNEL_AXIS = {"NCHW": 1, "NHWC": 3}
SPATIAL_AXES = {"NCHW": (2, 3), "NHWC": (1, 2)}
IMAGE_RANK = 4
RGB = 3
DEFAULT_PROVIDERS = ("CPUExecutionProvider",)
_PROVIDER_SUFFIX = "ExecutionProvider"


@dataclass(frozen=True)
class ModelIO:
    """What the adapter needs to know to feed the model and read its depth map."""

    input_name: str
    input_dtype: type
    layout: str  # "NCHW" | "NHWC"
    batch: int | None  # fixed batch size of the graph, None when dynamic
    fixed_hw: tuple[int | None, int | None]  # fixed input (H, W); None per dynamic side
    output_name: str
    output_squeeze_axis: int | None  # 1 or 3 for a rank-4 output; None: rank 3 or decide at run


def _fixed(dim) -> int | None:
    """A dimension as an int when the graph fixes it, None when symbolic or unknown."""
    return dim if isinstance(dim, int) and dim > 0 else None


def _describe(arg) -> str:
    return f"{arg.name!r} {arg.type} {list(arg.shape) if arg.shape is not None else '?'}"


def resolve_providers(providers) -> list[str]:
    """Turn ``None``, ``"cpu,cuda"`` or a list into available onnxruntime provider names.

    Short names are accepted case-insensitively (``cuda`` -> ``CUDAExecutionProvider``).
    """
    import onnxruntime as ort

    if providers is None:
        return list(DEFAULT_PROVIDERS)
    if isinstance(providers, str):
        providers = [p.strip() for p in providers.split(",") if p.strip()]
    available = ort.get_available_providers()
    by_key = {p.lower().removesuffix(_PROVIDER_SUFFIX.lower()): p for p in available}
    chosen = []
    for name in providers:
        key = name.lower().removesuffix(_PROVIDER_SUFFIX.lower())
        if key not in by_key:
            raise ValueError(
                f"onnxruntime provider {name!r} is not available here; available: {available}"
            )
        chosen.append(by_key[key])
    if not chosen:
        raise ValueError(f"no onnxruntime provider given; available: {available}")
    return chosen


def load_session(model, providers=None, session_options=None):
    """An ``onnxruntime.InferenceSession`` for a model path (or serialized model bytes)."""
    import onnxruntime as ort

    if isinstance(model, (bytes, bytearray)):
        source, where = bytes(model), "<bytes>"
    else:
        path = Path(model)
        if not path.is_file():
            raise FileNotFoundError(
                f"ONNX depth model not found: {path}; pass the path of an exported .onnx model "
                "(weights are not shipped with this package)"
            )
        source, where = str(path), str(path)
    try:
        return ort.InferenceSession(
            source, sess_options=session_options, providers=resolve_providers(providers)
        )
    except (ValueError, FileNotFoundError):
        raise
    except Exception as err:  # onnxruntime raises its own exception types
        raise ValueError(f"onnxruntime could not load the model {where}: {err}") from err


def _by_name(args, name: str, kind: str):
    """The model input or output (``kind``) called ``name``, or a clear error."""
    named = [a for a in args if a.name == name]
    if not named:
        raise ValueError(
            f"{kind}_name={name!r} is not an {kind} of the model; {kind}s: "
            f"{[a.name for a in args]}"
        )
    return named[0]


def _pick_image_input(inputs, input_name: str | None):
    if not inputs:
        raise ValueError("the ONNX model has no inputs; a depth model must take an image batch")
    if input_name is not None:
        return _by_name(inputs, input_name, "input")
    floats = [a for a in inputs if a.type in FLOAT_TYPES]
    if not floats:
        raise ValueError(
            "the ONNX model has no float input (inputs: "
            f"{', '.join(_describe(a) for a in inputs)}); a depth model must take a float "
            "image tensor"
        )
    if len(floats) == 1:
        return floats[0]
    images = [a for a in floats if a.shape is not None and len(a.shape) == IMAGE_RANK]
    if len(images) != 1:
        raise ValueError(
            f"the ONNX model has more than one float input ({[a.name for a in floats]}); "
            "say which one takes the image with input_name=..."
        )
    return images[0]


def _channel_layout(arg, layout: str | None) -> str:
    shape = list(arg.shape)
    if layout is not None:
        if layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
        channels = _fixed(shape[CHANNEL_AXIS[layout]])
        if channels not in (None, RGB):
            raise ValueError(
                f"input {_describe(arg)} has {channels} channels on the {layout} channel axis; "
                "expected 3 (RGB)"
            )
        return layout
    first, last = _fixed(shape[1]), _fixed(shape[3])
    if first == RGB:
        return "NCHW"
    if last == RGB:
        return "NHWC"
    if first is None and last is None:
        raise ValueError(
            f"cannot tell the channel axis of input {_describe(arg)}: both axis 1 and axis 3 are "
            "dynamic; pass layout='NCHW' or layout='NHWC'"
        )
    raise ValueError(
        f"input {_describe(arg)} has no 3-channel axis (axis 1 or axis 3 of size 3); "
        "a depth model must take RGB as [N, 3, H, W] or [N, H, W, 3]"
    )


def _pick_output(outputs, output_name: str | None):
    if not outputs:
        raise ValueError("the ONNX model has no outputs")
    if output_name is None:
        return outputs[0]
    return _by_name(outputs, output_name, "output")


def _output_squeeze_axis(arg) -> int | None:
    if arg.type not in FLOAT_TYPES:
        raise ValueError(
            f"output {_describe(arg)} is not a float tensor; a depth model must return a float "
            "depth map"
        )
    shape = list(arg.shape) if arg.shape is not None else []
    if len(shape) == 3:
        return None
    if len(shape) != IMAGE_RANK:
        raise ValueError(
            f"output {_describe(arg)} has rank {len(shape)}; expected a depth batch "
            "[N, H, W], [N, 1, H, W] or [N, H, W, 1]"
        )
    first, last = _fixed(shape[1]), _fixed(shape[3])
    if first == 1:
        return 1
    if last == 1:
        return 3
    if first is not None and last is not None:
        raise ValueError(
            f"output {_describe(arg)} has no single-channel axis; expected [N, 1, H, W] or "
            "[N, H, W, 1]"
        )
    return None


def discover(inputs, outputs, *, input_name=None, output_name=None, layout=None,
             extra_inputs=()) -> ModelIO:
    """Find the image input, its layout and fixed sizes, and the depth output.

    ``inputs``/``outputs`` are onnxruntime ``NodeArg`` lists (name, type, shape).
    Inputs other than the image must be named in ``extra_inputs`` (fed by the caller).
    """
    image = _pick_image_input(inputs, input_name)
    if image.type not in FLOAT_TYPES:
        raise ValueError(f"input {_describe(image)} is not a float tensor; an image input must be")
    shape = list(image.shape) if image.shape is not None else []
    if len(shape) != IMAGE_RANK:
        raise ValueError(
            f"input {_describe(image)} has rank {len(shape)}; expected a 4-D image batch "
            "[N, 3, H, W] (NCHW) or [N, H, W, 3] (NHWC)"
        )
    missing = [a.name for a in inputs if a.name != image.name and a.name not in extra_inputs]
    if missing:
        raise ValueError(
            f"the model needs inputs {missing} besides the image {image.name!r}; pass them as "
            "extra_feeds={name: array} or choose the image with input_name=..."
        )
    chosen_layout = _channel_layout(image, layout)
    h_axis, w_axis = SPATIAL_AXES[chosen_layout]
    output = _pick_output(outputs, output_name)
    return ModelIO(
        input_name=image.name,
        input_dtype=FLOAT_TYPES[image.type],
        layout=chosen_layout,
        batch=_fixed(shape[0]),
        fixed_hw=(_fixed(shape[h_axis]), _fixed(shape[w_axis])),
        output_name=output.name,
        output_squeeze_axis=_output_squeeze_axis(output),
    )


def to_nhw(prediction: np.ndarray, io: ModelIO) -> np.ndarray:
    """A model output as a float32 depth batch ``[N, H, W]``."""
    prediction = np.asarray(prediction)
    if prediction.ndim == 3:
        return prediction.astype(np.float32, copy=False)
    if prediction.ndim == IMAGE_RANK:
        axis = io.output_squeeze_axis
        if axis is None:
            axis = 1 if prediction.shape[1] == 1 else 3 if prediction.shape[3] == 1 else None
        if axis is not None and prediction.shape[axis] == 1:
            return np.squeeze(prediction, axis).astype(np.float32, copy=False)
    raise ValueError(
        f"output {io.output_name!r} returned shape {prediction.shape}; expected [N, H, W], "
        "[N, 1, H, W] or [N, H, W, 1]"
    )
