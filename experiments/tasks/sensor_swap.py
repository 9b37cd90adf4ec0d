"""Corrupt a scene's training depth the way a depth sensor or a depth network would
(:mod:`vbgs.sensors`). Test and validation views keep their exact depth: they are the
truth the scores are measured against.

Frame ``i`` of the training stream draws its noise from
``np.random.default_rng([seed, SENSOR_STREAM, i])``: a run is deterministic, every frame
gets noise of its own, and no other random stream of the task is disturbed.
"""

from __future__ import annotations

import numpy as np

from vbgs.data.scene import Scene
from vbgs.sensors import SENSOR_HOLES, SENSORS, check_level, parse_holes, refuse_holes, simulate

SENSOR_STREAM = 7  # second entry of each frame's rng seed: the sensor-noise stream


def simulate_training_depth(scene: Scene, sensor: str, level: float = 1.0,
                            seed: int = 0, holes: str = SENSOR_HOLES) -> tuple[Scene, dict]:
    """The scene with sensor ``sensor``'s depth on its training frames, its holes the
    sensor's own or those ``holes`` names (:func:`vbgs.sensors.parse_holes`), and the
    depth report: the source, the sensor, its level, the share of the training pixels
    with depth that became holes, and the median absolute depth error over the pixels
    kept."""
    if sensor not in SENSORS:
        raise ValueError(f"unknown simulate_sensor {sensor!r}: use one of {', '.join(SENSORS)}")
    level = check_level(level)
    spec = parse_holes(holes)
    if sensor == "exact":
        refuse_holes(sensor, spec)
        return scene, sensor_report(sensor, level, 0, 0, np.zeros(0))
    train, n_holes, with_depth, errors = [], 0, 0, []
    for i, frame in enumerate(scene.train):
        measured = simulate(sensor, frame.depth, frame.camera, seed=[seed, SENSOR_STREAM, i],
                            level=level, holes=spec)
        truth = frame.depth > 0
        n_holes += int(np.count_nonzero(truth & (measured == 0)))
        with_depth += int(np.count_nonzero(truth))
        kept = truth & (measured > 0)
        errors.append(np.abs(measured[kept].astype(np.float64) - frame.depth[kept]))
        train.append(frame._replace(depth=measured))
    report = sensor_report(sensor, level, n_holes, with_depth, np.concatenate(errors))
    return scene._replace(train=train), report


def learned_surface(scene: Scene, report: dict, sensor: str, level: float = 1.0
                    ) -> tuple[Scene, dict]:
    """The scene with each training frame's depth cut to what sensor ``sensor`` says is
    surface (``SENSORS[sensor].surface``: a depth network's far field and the depth it
    bled across edges are not), and the report with the share of the training pixels
    with depth so cut (``depth_not_surface``). Each frame's cut reads its own depth only.
    """
    model = SENSORS[sensor]
    train = [f._replace(depth=model.surface(f.depth, f.camera, level)) for f in scene.train]
    cut = sum(int(np.count_nonzero((f.depth > 0) & (g.depth == 0)))
              for f, g in zip(scene.train, train, strict=True))
    with_depth = sum(int(np.count_nonzero(f.depth > 0)) for f in scene.train)
    return (scene._replace(train=train),
            {**report, "depth_not_surface": cut / with_depth if with_depth else 0.0})


def sensor_report(sensor: str, level: float, holes: int, with_depth: int,
                  errors: np.ndarray) -> dict:
    """The record the run's JSON shows (flat keys, as the sweep's tables read them)."""
    return {
        "depth_source": "sensor" if sensor == "exact" else "simulated",
        "depth_sensor": sensor,
        "depth_sensor_level": level,
        "depth_sensor_holes": holes / with_depth if with_depth else 0.0,
        "depth_sensor_abs_error": float(np.median(errors)) if errors.size else 0.0,
    }


class AlignedArrivals:
    """``arrivals(frames) -> frames``: each arriving training frame's depth aligned to
    the frames that arrived before it (:func:`depth.perframe.align_frame`), lazily, in
    arrival order: the stage a depth network's depth goes through (``--sensor mono``).
    The ``mono`` sensor model is what a network gives after one alignment for the whole
    stream; an ONNX model's depth gets the same stage inside :mod:`depth.stream`."""

    def __init__(self, config, report: dict):
        self.config = config
        self.base = report
        self.fits: list = []

    def __call__(self, frames):
        from depth.perframe import align_frame, init

        state, self.fits = init(), []
        for frame in frames:
            state, depth, fit = align_frame(state, frame.camera, frame.depth, self.config)
            self.fits.append(fit)
            yield frame._replace(depth=depth)

    def report(self) -> dict:
        """The sensor report and the spread of the per-frame corrections."""
        return {**self.base, **per_frame_report(self.fits)}


def per_frame_report(fits) -> dict:
    """Flat keys: frames aligned to earlier ones, the SD of their scale terms and the
    median of their residuals (relative depth disagreement with the earlier frames)."""
    used = [f for f in fits if f.n_pairs > 0 and np.isfinite(f.residual)]
    return {
        "depth_per_frame_aligned": len(used),
        "depth_per_frame_scale_sd": float(np.std([f.coef[0] for f in used])) if used else 0.0,
        "depth_per_frame_residual": float(np.median([f.residual for f in used]))
        if used else float("nan"),
    }
