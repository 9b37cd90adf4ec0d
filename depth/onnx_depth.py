"""OnnxDepth: any user-supplied ONNX monocular depth model as ``frames -> depth maps``.

Pipeline per batch of frames ``[n, h, w, 3]`` (RGB in [0, 1])::

    resize to (H, W)  ->  x_c = (rgb_c - mean_c) / std_c  ->  layout (NCHW / NHWC)
    ->  session.run  ->  [N, H', W']  ->  resize back to (h, w)  ->  float32

The values are returned as the model gives them; ``kind`` records what they mean
("metric", "inverse" or "relative", see :mod:`depth.presets`) so that
:func:`depth.align.align` can turn them into metric depth.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from depth.model_io import discover, load_session, to_nhw
from depth.preprocess import as_frames, input_hw, resize, to_model_input
from depth.presets import NO_MEAN, NO_STD, check_kind, get_preset

DEFAULT_BATCH_SIZE = 4
DEFAULT_KIND = "metric"
DEFAULT_KEEP_ASPECT = True
DEFAULT_MULTIPLE_OF = 1


def _rgb_triple(values, what: str) -> tuple[float, float, float]:
    values = tuple(float(v) for v in np.broadcast_to(np.asarray(values, np.float64), (3,)))
    if not all(np.isfinite(values)):
        raise ValueError(f"{what} must be finite, got {values}")
    return values


class OnnxDepth:
    """Monocular depth from an ONNX model through onnxruntime.

    Args:
      model_path: path of the ``.onnx`` file (or its serialized bytes).
      kind: "metric" | "inverse" | "relative"; default: the preset's, else "metric".
      preset: a key of :data:`depth.presets.PRESETS` giving size, mean/std and kind.
      providers: onnxruntime providers, e.g. ``["cuda", "cpu"]``; default CPU only.
      input_size: shorter side (with ``keep_aspect``) or square side, or ``(H, W)``;
        None: the frame's own size. Sides the graph fixes always win.
      mean, std: per-channel normalisation ``(rgb - mean) / std``; default none.
      keep_aspect: keep the frame's aspect ratio when ``input_size`` is one number.
      multiple_of: round each free input side to a multiple of this.
      batch_size: frames per ``session.run`` (the graph's fixed batch, if any, wins).
      input_name: which input takes the image, when the model has several.
      output_name: which output is depth (default: the first).
      layout: "NCHW" | "NHWC" when the graph does not fix a 3-channel axis.
      extra_feeds: constant arrays for inputs other than the image.
      session_options: an ``onnxruntime.SessionOptions``.
    """

    def __init__(
        self,
        model_path,
        *,
        kind: str | None = None,
        preset: str | None = None,
        providers=None,
        input_size: int | tuple[int, int] | None = None,
        mean: Sequence[float] | None = None,
        std: Sequence[float] | None = None,
        keep_aspect: bool | None = None,
        multiple_of: int | None = None,
        batch_size: int = DEFAULT_BATCH_SIZE,
        input_name: str | None = None,
        output_name: str | None = None,
        layout: str | None = None,
        extra_feeds: Mapping[str, np.ndarray] | None = None,
        session_options=None,
    ):
        p = get_preset(preset)
        self.kind = check_kind(kind if kind is not None else p.kind if p else DEFAULT_KIND)
        self.mean = _rgb_triple(mean if mean is not None else p.mean if p else NO_MEAN, "mean")
        self.std = _rgb_triple(std if std is not None else p.std if p else NO_STD, "std")
        if min(self.std) <= 0:
            raise ValueError(f"std must be positive, got {self.std}")
        self.keep_aspect = bool(
            keep_aspect if keep_aspect is not None else p.keep_aspect if p else DEFAULT_KEEP_ASPECT
        )
        self.multiple_of = int(
            multiple_of if multiple_of is not None else p.multiple_of if p else DEFAULT_MULTIPLE_OF
        )
        if self.multiple_of < 1:
            raise ValueError(f"multiple_of must be >= 1, got {self.multiple_of}")
        self.input_size = input_size if input_size is not None else p.input_size if p else None
        self.extra_feeds = dict(extra_feeds or {})
        self.session = load_session(model_path, providers, session_options)
        self.io = discover(
            self.session.get_inputs(), self.session.get_outputs(), input_name=input_name,
            output_name=output_name, layout=layout, extra_inputs=tuple(self.extra_feeds),
        )
        self._check_explicit_size(input_size)
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.batch_size = self.io.batch or int(batch_size)

    def _check_explicit_size(self, input_size) -> None:
        if not isinstance(input_size, (tuple, list)):
            return
        sides = zip(input_size, self.io.fixed_hw, ("height", "width"), strict=True)
        for want, fixed, side in sides:
            if fixed is not None and fixed != want:
                raise ValueError(
                    f"input_size {tuple(input_size)} disagrees with the model's fixed input "
                    f"{side} {fixed}; leave input_size unset to use the model's size"
                )

    @property
    def providers(self) -> list[str]:
        return self.session.get_providers()

    def input_hw(self, frame_hw: tuple[int, int]) -> tuple[int, int]:
        """The model input size ``(H, W)`` used for frames of size ``frame_hw``."""
        return input_hw(
            frame_hw, self.input_size, self.keep_aspect, self.multiple_of, self.io.fixed_hw
        )

    def preprocess(self, rgb: np.ndarray) -> np.ndarray:
        """Checked frames ``[n, h, w, 3]`` in [0, 1] -> the model's input tensor."""
        x = resize(rgb, self.input_hw(rgb.shape[1:3]), (1, 2))
        return to_model_input(x, self.mean, self.std, self.io.layout, self.io.input_dtype)

    def run(self, x: np.ndarray) -> np.ndarray:
        """One ``session.run`` on a prepared input -> float32 ``[N, H', W']``."""
        feeds = {self.io.input_name: x, **self.extra_feeds}
        out = self.session.run([self.io.output_name], feeds)[0]
        return to_nhw(out, self.io)

    def predict(self, frames) -> np.ndarray:
        """Depth-like maps of ``self.kind`` for one frame ``[h, w, 3]`` -> ``[h, w]``,
        or for frames ``[n, h, w, 3]`` (array or list) -> ``[n, h, w]``; float32.
        """
        rgb, single = as_frames(frames)
        n, h, w, _ = rgb.shape
        out = np.empty((n, h, w), np.float32)
        for start in range(0, n, self.batch_size):
            chunk = rgb[start:start + self.batch_size]
            k = len(chunk)
            if self.io.batch is not None and k < self.io.batch:  # fixed batch: pad with copies
                chunk = np.concatenate([chunk, np.repeat(chunk[-1:], self.io.batch - k, 0)])
            pred = self.run(self.preprocess(chunk))
            if pred.shape[0] != len(chunk):
                raise ValueError(
                    f"model returned {pred.shape[0]} depth maps for {len(chunk)} frames "
                    f"(output shape {pred.shape}); the output's first axis must be the batch"
                )
            out[start:start + k] = resize(pred[:k], (h, w), (1, 2))
        return out[0] if single else out

    def __call__(self, frames) -> np.ndarray:
        return self.predict(frames)

    def __repr__(self) -> str:
        return (
            f"OnnxDepth(kind={self.kind!r}, layout={self.io.layout}, "
            f"input={self.io.input_name!r} fixed_hw={self.io.fixed_hw}, "
            f"input_size={self.input_size}, multiple_of={self.multiple_of}, "
            f"mean={self.mean}, std={self.std}, batch_size={self.batch_size}, "
            f"providers={self.providers})"
        )

