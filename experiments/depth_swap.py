"""Replace a scene's sensor depth by monocular estimates (RGB-only input).

The estimates come from a user-supplied ONNX model through :class:`depth.OnnxDepth`.
Inverse or relative predictions are made metric by one global alignment fitted
against the first training frame's sensor depth at a sparse random subset of its
pixels (``REFERENCE_FRACTION``), the way a robot would calibrate once on a few
measured points. Test views keep their ground truth: evaluation stays honest.
"""

from __future__ import annotations

import numpy as np

from depth import OnnxDepth, align, apply
from depth.align import DEFAULT_METHOD
from vbgs.data.scene import Scene

REFERENCE_FRACTION = 0.01  # share of the first frame's valid pixels used to align


def estimate_scene_depth(scene: Scene, model_path: str, *, kind: str = "inverse",
                         preset: str | None = None, align_method: str = "auto",
                         seed: int = 0) -> tuple[Scene, dict]:
    """The scene with estimated depth on its training frames, and a report of the
    alignment (scale, shift, residual) and of the estimates' error (mean absolute
    relative error against the sensor depth, where that is valid)."""
    net = OnnxDepth(model_path, kind=kind, preset=preset)
    predictions = net.predict(np.stack([f.rgb for f in scene.train]))  # [n, h, w]
    method = DEFAULT_METHOD[net.kind] if align_method == "auto" else align_method
    reference = scene.train[0].depth
    valid = np.flatnonzero(reference.ravel() > 0)
    rng = np.random.default_rng(seed)
    picked = rng.choice(valid, max(8, int(REFERENCE_FRACTION * len(valid))), replace=False)
    fit = align(predictions[0], reference, picked, method=method, seed=seed)
    train, errors = [], []
    for frame, pred in zip(scene.train, predictions, strict=True):
        est = apply(fit, pred).astype(np.float32)
        ok = (frame.depth > 0) & (est > 0)
        if ok.any():
            errors.append(np.mean(np.abs(est[ok] - frame.depth[ok]) / frame.depth[ok]))
        train.append(frame._replace(depth=est))
    report = {
        "depth_source": "estimated",
        "depth_align_method": method,
        "depth_align_scale": float(fit.scale),
        "depth_align_shift": float(fit.shift),
        "depth_align_residual": float(fit.residual),
        "depth_abs_rel": float(np.mean(errors)) if errors else float("nan"),
    }
    return scene._replace(train=train), report
