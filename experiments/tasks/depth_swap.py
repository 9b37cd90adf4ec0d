"""Training depth from an ONNX depth model, estimated as the frames arrive (RGB-only input).

:class:`EstimatedDepth` sits between the scene's frames and the stream protocol
(``stream_protocol(..., arrive=...)``): each arriving frame goes through the model
(:class:`depth.OnnxDepth`) and :mod:`depth.stream`, which aligns the predictions to
metric depth from the frames that have arrived (the views' multi-view consistency,
or a few frames of sensor depth) and cuts the network's far field and depth edges
out of the surface. The frames come out with that depth, in arrival order; the
first few may come out together, once the alignment could be read from them. Test and
validation views keep their depth (an RGB-only folder's have none: RGB scores only).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from depth import OnnxDepth
from depth.stream import StreamConfig, StreamState, arrive, check_config, finish, init
from experiments.tasks.sensor_swap import per_frame_report
from vbgs.data.scene import Frame


class EstimatedDepth:
    """``arrivals(frames) -> frames``: the frames with the model's metric depth, read
    lazily (a frame is pulled only when the stream reaches it). ``report()`` after
    the stream: how it was aligned and, where frames had sensor depth, the estimate's
    error against it."""

    def __init__(self, model_path: str, config: StreamConfig, *, preset: str | None = None,
                 positions: list[int] | None = None):
        self.net = OnnxDepth(model_path, kind=config.kind, preset=preset)
        self.config = check_config(config._replace(kind=self.net.kind))
        self.positions = positions  # arrival position -> training frame index, for the report
        self.state: StreamState = init()
        self.errors: list[float] = []
        self.cut = [0, 0]  # pixels made depth-less, pixels released

    def __call__(self, frames: Iterable[Frame]) -> Iterator[Frame]:
        self.state = init()
        for frame in frames:
            prediction = self.net.predict(frame.rgb)  # [h, w]
            self.state, ready = arrive(self.state, frame, prediction, self.config)
            yield from self._released(ready)
        self.state, ready = finish(self.state, self.config)
        yield from self._released(ready)

    def _released(self, ready) -> Iterator[Frame]:
        for frame, depth in ready:
            sensor = np.asarray(frame.depth)
            ok = (sensor > 0) & (depth > 0)
            if ok.any():
                self.errors.append(float(np.mean(np.abs(depth[ok] - sensor[ok]) / sensor[ok])))
            self.cut[0] += int(np.count_nonzero(depth == 0))
            self.cut[1] += depth.size
            yield frame._replace(depth=depth)

    def report(self) -> dict:
        """The run's depth record (flat keys, as the sweep's tables read them)."""
        fit, on = self.state.alignment, self.state.aligned_on
        if self.positions is not None:
            on = tuple(int(self.positions[p]) for p in on)
        return {
            "depth_source": "estimated",
            "depth_reference": self.state.reference,
            "depth_aligned_on": list(on),  # training frame indices the alignment read
            "depth_align_scale": float(fit.scale) if fit else float("nan"),
            "depth_align_shift": float(fit.shift) if fit else float("nan"),
            "depth_align_space": fit.space if fit else None,
            "depth_align_residual": float(fit.residual) if fit else float("nan"),
            "depth_abs_rel": float(np.mean(self.errors)) if self.errors else float("nan"),
            "depth_not_surface": self.cut[0] / self.cut[1] if self.cut[1] else 0.0,
            **per_frame_report(self.state.fits),
        }
