"""RGB-only study: sensor depth against depth estimated by an ONNX model, per method.

No network weights ship with the project, so the "network" here is a test model
(:func:`depth.testing.lookup_model`) that returns, for each training frame, the depth
of the ``mono`` sensor model (:mod:`vbgs.sensors.mono`: a depth network's per-frame
scale and shift drift, smooth warp, edges bled, depth on the empty background) as a
relative disparity under an unknown affine map, ``p = a / d_mono + b``. It is the same
corrupted depth ``fit-scene --simulate-sensor mono`` trains on (frame ``i`` drawn from
``[seed, SENSOR_STREAM, i]``), delivered as a network would deliver it. The RGB-only
path is then exercised end to end: ONNX inference through :class:`depth.OnnxDepth`
frame by frame as the stream arrives, alignment to metric depth from the first
arrived frames' multi-view consistency (no sensor depth: ``depth_reference="views"``),
the far field and edges cut out of the surface, the learners told the depth is a
network's (``sensor="mono"``), and the same held-out evaluation as with sensor depth.
The written table carries the command and every setting that made it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.tasks.scene_task import SceneTask, load_task_scene, run_scene
from experiments.tasks.sensor_swap import SENSOR_STREAM
from vbgs.sensors import simulate

# The test depth model's affine map: relative disparity p = A / d_mono + B.
DISPARITY_SCALE = 2.0
DISPARITY_SHIFT = 0.3


def require_onnx():
    """The ``onnx`` module, which builds the study's test model; a clear ImportError
    naming the extra to install when it is missing."""
    try:
        import onnx
    except ImportError as err:
        raise ImportError("depth-study builds its test depth model with the 'onnx' package, "
                          "which is not installed: pip install -e '.[depth-study]' "
                          "(or pip install onnx)") from err
    return onnx


def mono_disparity(frames, seed: int, scale: float = DISPARITY_SCALE,
                   shift: float = DISPARITY_SHIFT) -> np.ndarray:
    """``[m, h, w]`` float32: ``scale / d_mono + shift`` of each training frame, ``d_mono``
    the ``mono`` sensor's depth of frame ``i`` drawn as ``--simulate-sensor mono`` draws
    it (:func:`experiments.tasks.sensor_swap.simulate_training_depth`)."""
    out = [scale / simulate("mono", f.depth, f.camera, seed=[seed, SENSOR_STREAM, i]) + shift
           for i, f in enumerate(frames)]
    return np.stack(out).astype(np.float32)


def write_lookup_model(task: SceneTask, path: Path) -> Path:
    """Save the test depth model (:func:`mono_disparity` of the task's training frames)."""
    onnx = require_onnx()
    from depth.testing import lookup_model

    scene = load_task_scene(task)
    model = lookup_model(np.stack([f.rgb for f in scene.train]),
                         mono_disparity(scene.train, task.seed))
    path.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(path))
    return path


def study_settings(task_kw: dict, methods) -> dict:
    """Every setting a depth-study table depends on, for its header and CSV columns."""
    return {**task_kw, "methods": " ".join(methods), "estimated": "mono sensor model",
            "disparity_scale": DISPARITY_SCALE, "disparity_shift": DISPARITY_SHIFT,
            "depth_reference": "views", "estimated_learned_as": "mono"}


def study_command(task_kw: dict, methods, out) -> str:
    """The ``python -m experiments.run depth-study`` line that reproduces a table."""
    return ("python -m experiments.run depth-study "
            f"--scene {task_kw['scene']} --components {task_kw['components']} "
            f"--frames {task_kw['frames']} --size {task_kw['size']} "
            f"--methods {' '.join(methods)} --steps-per-frame {task_kw['steps_per_frame']} "
            f"--out {out}")


def run_depth_study(out_dir: str | Path, *, methods=("vbgs", "gradient"), progress=False,
                    **task_kw) -> list[dict]:
    """Held-out metrics with sensor and with estimated depth for each method."""
    out = Path(out_dir)
    base = SceneTask(**task_kw)
    model_path = write_lookup_model(base, out / "depth_lookup.onnx")
    rows = []
    for method in methods:
        for source in ("sensor", "estimated"):
            estimated = source == "estimated"
            task = SceneTask(**{**task_kw, "method": method,
                                "depth_model": str(model_path) if estimated else None,
                                "depth_kind": "inverse", "depth_reference": "views",
                                "sensor": "mono" if estimated else "exact"})
            result = run_scene(task, progress=progress)
            rows.append({
                "method": method, "depth": source, "psnr": result.psnr,
                "ssim": result.ssim, "depth_l1": result.depth_l1,
                "train_depth_abs_rel": result.depth.get("depth_abs_rel", 0.0),
                "align_scale": result.depth.get("depth_align_scale", float("nan")),
                "align_shift": result.depth.get("depth_align_shift", float("nan")),
                "seconds": result.seconds, "dropped": result.dropped,
            })
    return rows
