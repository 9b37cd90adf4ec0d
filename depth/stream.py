"""Metric depth for a stream of RGB frames, aligned from the frames that have arrived.

A depth network's output ``p`` becomes metric depth by one alignment ``(s, t)``
(:mod:`depth.align`) fitted as the stream runs, never on a frame that has not arrived:

* ``reference="views"``: from multi-view consistency of the first ``views`` frames to
  arrive, with their known poses (:func:`depth.multiview.align_views`); no sensor depth
  at all. Those frames are held until the last of them arrives, then released in
  arrival order, every one with that alignment; every later frame takes it as it
  arrives. So frame ``t`` (in stream order, whatever the order of the files) is made
  metric by an alignment read from frames ``0 .. max(t, views - 1)``, all of which have
  arrived when it is released.
* ``reference="sensor"``: from the sensor depth of the first arrived frame that has some
  (``REFERENCE_FRACTION`` of its pixels with depth, :func:`depth.align.align`), as a robot
  calibrates once on a few measured points; frames before it are held.
* ``reference="auto"``: "sensor" when the first arrived frame has sensor depth, else
  "views".
* ``kind="metric"``: the output is metric already; nothing is fitted or held.

Each released frame's depth is the aligned prediction cut to what a network's depth
shows of the surface (below), then aligned once more, on its own, to the frames released
before it (:func:`depth.perframe.align_frame`, ``StreamConfig.per_frame``; None turns it
off): one alignment for the stream leaves each frame a scale, shift and warp error of its
own, the same errors the ``mono`` sensor model simulates, whose in-memory path
(``--simulate-sensor mono --sensor mono``) goes through the same function. The cut is
the surface (:meth:`vbgs.sensors.mono.Mono.surface`): its far field (sky,
empty background) and its depth edges become depth-less, so the background and the
opacity evidence treat them as empty, and no shell of splats forms around the scene.

The state is an immutable :class:`StreamState`; :func:`arrive` and :func:`finish` return
a new state and the frames released, ``(frame, depth)`` pairs in arrival order.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from depth.align import DEFAULT_METHOD, Alignment, align, apply
from depth.multiview import View, align_views
from depth.perframe import AlignState, FrameAlignConfig, align_frame
from vbgs.sensors import SENSORS

REFERENCES = ("auto", "sensor", "views")
ALIGN_VIEWS = 6  # frames the views' alignment is read from (held until the last arrives)
REFERENCE_FRACTION = 0.01  # share of a sensor frame's pixels with depth used to align
MIN_REFERENCE_PIXELS = 8
SURFACE = SENSORS["mono"]  # what of a network's depth is surface


class StreamConfig(NamedTuple):
    """How the stream's depth is made metric."""

    kind: str = "inverse"  # the network's output: metric | inverse | relative
    method: str = "auto"  # sensor reference: an alignment method of depth.align
    reference: str = "auto"  # auto | sensor | views
    views: int = ALIGN_VIEWS
    seed: int = 0
    # each released frame then aligned to the frames released before it
    # (depth.perframe); None: the one alignment only
    per_frame: FrameAlignConfig | None = FrameAlignConfig()


class Arrived(NamedTuple):
    """A held frame: its arrival position, the frame and the network's prediction."""

    position: int
    frame: object  # anything with rgb [h, w, 3], depth [h, w] (sensor; 0 = none), camera
    prediction: np.ndarray  # [h, w]


class StreamState(NamedTuple):
    """What the stream holds between frames."""

    held: tuple = ()  # Arrived frames waiting for the alignment
    alignment: Alignment | None = None
    reference: str | None = None  # "views" | "sensor" | "metric", once fitted
    aligned_on: tuple = ()  # arrival positions the alignment read
    arrived: int = 0
    frames: AlignState = AlignState()  # the per-frame alignment's reference frames
    fits: tuple = ()  # FrameFit of each released frame, in arrival order


def check_config(config: StreamConfig) -> StreamConfig:
    """The config, or ValueError naming the bad field and the choices."""
    if config.reference not in REFERENCES:
        raise ValueError(f"unknown depth reference {config.reference!r}: use one of "
                         f"{', '.join(REFERENCES)}")
    if not (isinstance(config.views, int) and config.views >= 2):
        raise ValueError(f"aligning by the views needs at least 2 views, got {config.views!r}")
    return config


def init() -> StreamState:
    """The state before any frame has arrived."""
    return StreamState()


def _has_depth(frame) -> bool:
    return bool(np.any(np.asarray(frame.depth) > 0))


def _sensor_alignment(held: Arrived, config: StreamConfig) -> Alignment:
    """:func:`depth.align.align` of one frame's prediction on ``REFERENCE_FRACTION`` of
    its sensor depth (seeded)."""
    method = DEFAULT_METHOD[config.kind] if config.method == "auto" else config.method
    depth = np.asarray(held.frame.depth)
    valid = np.flatnonzero(depth.ravel() > 0)
    rng = np.random.default_rng(config.seed)
    picked = rng.choice(valid, min(len(valid), max(MIN_REFERENCE_PIXELS,
                                                   int(REFERENCE_FRACTION * len(valid)))),
                        replace=False)
    return align(held.prediction, depth, picked, method=method, seed=config.seed)


def _fit(state: StreamState, config: StreamConfig, final: bool) -> StreamState:
    """The state with its alignment fitted, if the held frames allow it now (``final``:
    the stream has ended, fit on what arrived)."""
    held = state.held
    if config.kind == "metric":
        return state._replace(alignment=Alignment(1.0, 0.0, "depth", float("nan"),
                                                  float("nan"), 0), reference="metric")
    reference = config.reference
    if reference == "auto":
        reference = "sensor" if _has_depth(held[0].frame) else "views"
    if reference == "sensor":
        with_depth = [h for h in held if _has_depth(h.frame)]
        if not with_depth:
            if final:
                raise ValueError(f"--depth-reference sensor: none of the {state.arrived} "
                                 f"frames has sensor depth to align the depth model on; "
                                 f"use --depth-reference views (the frames' poses)")
            return state
        return state._replace(alignment=_sensor_alignment(with_depth[0], config),
                              reference="sensor", aligned_on=(with_depth[0].position,))
    if len(held) < config.views and not final:
        return state
    views = [View(h.frame.camera, h.frame.rgb, h.prediction) for h in held]
    return state._replace(alignment=align_views(views, config.kind, seed=config.seed),
                          reference="views", aligned_on=tuple(h.position for h in held))


def metric_depth(state: StreamState, prediction: np.ndarray, camera) -> np.ndarray:
    """The aligned prediction ``[h, w]`` (float32) cut to the surface a network's depth
    shows (module docstring)."""
    return SURFACE.surface(apply(state.alignment, prediction), camera)


def _release(state: StreamState, config: StreamConfig) -> tuple[StreamState, list]:
    ready = []
    for h in state.held:
        depth = metric_depth(state, h.prediction, h.frame.camera)
        if config.per_frame is not None:
            frames, depth, fit = align_frame(state.frames, h.frame.camera, depth,
                                             config.per_frame)
            state = state._replace(frames=frames, fits=(*state.fits, fit))
        ready.append((h.frame, depth))
    return state._replace(held=()), ready


# A prediction whose finite values span less than this share of their largest magnitude
# is one value: the network saw nothing it could tell apart.
CONSTANT_SPREAD = 1e-6


def prediction_problem(prediction: np.ndarray) -> str | None:
    """What makes a network's raw output ``[h, w]`` unusable as depth, in words naming the
    output (its range), or None: no finite value, none > 0, or one value everywhere."""
    pred = np.asarray(prediction, np.float64)
    finite = pred[np.isfinite(pred)]
    if not finite.size:
        return f"the model's output is NaN or infinite at all {pred.size} pixels"
    lo, hi = float(finite.min()), float(finite.max())
    spans = f"the model's output spans {lo:.4g} to {hi:.4g}"
    if hi <= 0:
        return f"{spans}: no pixel is > 0 (depth is positive; inverse depth too)"
    if hi - lo <= CONSTANT_SPREAD * max(abs(lo), abs(hi)):
        return f"the model's output is {hi:.4g} at every finite pixel: one value, no shape"
    return None


def arrive(state: StreamState, frame, prediction: np.ndarray, config: StreamConfig
           ) -> tuple[StreamState, list]:
    """One frame arrives with the network's ``prediction [h, w]``: the new state and the
    frames released now, ``[(frame, depth [h, w])]`` in arrival order (none while the
    alignment waits for more frames). A prediction no depth can come from
    (:func:`prediction_problem`) is refused, naming the model's output."""
    problem = prediction_problem(prediction)
    if problem:
        raise ValueError(f"--depth-model, frame {state.arrived}: {problem}; check the model "
                         f"and --depth-kind (python -m depth on the frames says more)")
    state = state._replace(held=(*state.held, Arrived(state.arrived, frame,
                                                      np.asarray(prediction))),
                           arrived=state.arrived + 1)
    if state.alignment is None:
        state = _fit(state, config, final=False)
        if state.alignment is None:
            return state, []
    return _release(state, config)


def finish(state: StreamState, config: StreamConfig) -> tuple[StreamState, list]:
    """The stream has ended: align on what arrived if not done yet, release the rest."""
    if not state.held:
        return state, []
    if state.alignment is None:
        state = _fit(state, config, final=True)
    return _release(state, config)
