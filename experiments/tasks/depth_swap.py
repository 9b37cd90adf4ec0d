"""Training depth from an ONNX depth model, estimated as the frames arrive (RGB-only input).

:class:`EstimatedDepth` sits between the scene's frames and the stream protocol
(``stream_protocol(..., arrive=...)``): each arriving frame goes through the model
(:class:`depth.OnnxDepth`) and :mod:`depth.stream`, which aligns the predictions to
metric depth from the frames that have arrived (the views' multi-view consistency,
or a few frames of sensor depth) and cuts the network's far field and depth edges
out of the surface. The frames come out with that depth, in arrival order; the
first few may come out together, once the alignment could be read from them. Test and
validation views keep their depth (an RGB-only folder's have none: RGB scores only).
:class:`SimulatedNetwork` is the same stage for the ``mono`` sensor model simulated in
memory: its depth handed over as a network's output, with no metric scale.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from depth import OnnxDepth
from depth.stream import StreamConfig, StreamState, arrive, check_config, finish, init
from experiments.tasks.sensor_swap import per_frame_report
from vbgs.data.scene import Frame
from vbgs.sensors.mono import network_output, network_units

NETWORK_STREAM = 11  # second entry of the rng seed of a simulated network's unit and offset


class StreamedDepth:
    """``arrivals(frames) -> frames``: the frames with metric depth from a network's
    output (:meth:`predict`, one frame at a time) made metric by :mod:`depth.stream`,
    read lazily (a frame is pulled only when the stream reaches it). ``report()`` after
    the stream: how it was aligned and, where frames had depth, the estimate's error
    against it."""

    source = "estimated"  # the record's depth_source

    def __init__(self, config: StreamConfig, *, positions: list[int] | None = None):
        self.config = check_config(config)
        self.positions = positions  # arrival position -> training frame index, for the report
        self.state: StreamState = init()
        self.errors: list[float] = []
        self.cut = [0, 0]  # pixels made depth-less, pixels released

    def predict(self, frame: Frame) -> np.ndarray:
        """The network's output ``[h, w]`` for one arrived frame."""
        raise NotImplementedError

    def __call__(self, frames: Iterable[Frame]) -> Iterator[Frame]:
        self.state = init()
        for frame in frames:
            self.state, ready = arrive(self.state, frame, self.predict(frame), self.config)
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
            "depth_source": self.source,
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


class EstimatedDepth(StreamedDepth):
    """:class:`StreamedDepth` of an ONNX depth model (:class:`depth.OnnxDepth`) on each
    arriving frame's RGB."""

    def __init__(self, model_path: str, config: StreamConfig, *, preset: str | None = None,
                 positions: list[int] | None = None):
        self.net = OnnxDepth(model_path, kind=config.kind, preset=preset)
        super().__init__(config._replace(kind=self.net.kind), positions=positions)

    def predict(self, frame: Frame) -> np.ndarray:
        return self.net.predict(frame.rgb)


class SimulatedNetwork(StreamedDepth):
    """:class:`StreamedDepth` of a simulated depth network: each arriving frame's
    simulated ``mono`` depth (:func:`experiments.tasks.sensor_swap.simulate_training_depth`,
    at the sequence's true scale) handed over as the network would give it, inverse
    depth in a unit and with an offset of its own drawn from ``seed``
    (:func:`vbgs.sensors.mono.network_output`). The metric scale is then found from the
    frames that have arrived, with their poses (``reference="views"``: a user's
    RGB-only stream has no sensor depth), as for a real network; the frames' ``depth``
    (the simulated depth) is read by the report alone (``depth_abs_rel``: what the
    alignment from arrived frames adds to the simulated network's own error)."""

    source = "simulated"

    def __init__(self, config: StreamConfig, *, seed: int = 0,
                 positions: list[int] | None = None):
        self.unit, self.offset = network_units(np.random.default_rng([seed, NETWORK_STREAM]))
        super().__init__(config._replace(kind="inverse", reference="views"),
                         positions=positions)

    def predict(self, frame: Frame) -> np.ndarray:
        return network_output(frame.depth, self.unit, self.offset)


def simulated_network(task) -> bool:
    """Whether the task's training depth is a simulated depth network's learned as one
    (``simulate_sensor`` and ``sensor`` both ``mono``): its metric scale is then found
    from the arrived frames (:class:`SimulatedNetwork`)."""
    return task.simulate_sensor == "mono" and task.sensor == "mono" and not task.depth_model


def depth_arrivals(task, scene, order, report: dict | None = None):
    """The stage the arriving training frames pass through: with a depth model, its
    metric depth (:class:`experiments.tasks.depth_swap.EstimatedDepth`, which aligns each
    frame to the frames before it); for a simulated depth network, the same from its
    output (:class:`experiments.tasks.depth_swap.SimulatedNetwork`: the metric scale found
    from the arrived frames' views); for a folder's network depth (``sensor "mono"``)
    the per-frame alignment alone (:class:`experiments.tasks.sensor_swap.AlignedArrivals`,
    ``report`` the sensor report it extends); otherwise None (the depth as it is:
    exact-depth runs are unchanged)."""
    if simulated_network(task):
        return SimulatedNetwork(StreamConfig(seed=task.seed), seed=task.seed,
                                positions=[int(i) for i in order])
    if not task.depth_model:
        if task.sensor == "mono":  # a network's depth: each frame aligned as it arrives
            from depth.perframe import FrameAlignConfig
            from experiments.tasks.sensor_swap import AlignedArrivals

            return AlignedArrivals(FrameAlignConfig(), report)
        return None
    config = StreamConfig(kind=task.depth_kind, method=task.depth_align,
                          reference=task.depth_reference, seed=task.seed)
    return EstimatedDepth(task.depth_model, config, preset=task.depth_preset,
                          positions=[int(i) for i in order])
