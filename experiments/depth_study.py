"""RGB-only study: sensor depth against depth estimated by an ONNX model, per method.

No network weights ship with the project, so the "network" here is a test model
(:func:`depth.testing.depth_lookup_model`) that returns the true inverse depth of the
scene under a known affine distortion plus fixed noise, ``p = a / depth + b + e``:
the "estimated" depth is a synthetic distortion of the true depth, not the output of
a learned model. The RGB-only path is then exercised end to end: ONNX inference
through :class:`depth.OnnxDepth`, alignment to metric depth from 1% of the first
frame's pixels, and the same stream protocol and held-out evaluation as with sensor
depth. The written table carries the command and every setting that made it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.scene_task import SceneTask, load_task_scene, run_scene

# Distortion of the test depth model: relative disparity p = A / depth + B + noise.
DISPARITY_SCALE = 2.0
DISPARITY_SHIFT = 0.3
DISPARITY_NOISE = 0.01


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


def write_lookup_model(task: SceneTask, path: Path) -> Path:
    """Save the distorted-depth test model for the task's training frames."""
    onnx = require_onnx()
    from depth.testing import depth_lookup_model

    scene = load_task_scene(task)
    model = depth_lookup_model(np.stack([f.rgb for f in scene.train]),
                               np.stack([f.depth for f in scene.train]),
                               DISPARITY_SCALE, DISPARITY_SHIFT, DISPARITY_NOISE, seed=task.seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(path))
    return path


def study_settings(task_kw: dict, methods) -> dict:
    """Every setting a depth-study table depends on, for its header and CSV columns."""
    return {**task_kw, "methods": " ".join(methods), "disparity_scale": DISPARITY_SCALE,
            "disparity_shift": DISPARITY_SHIFT, "disparity_noise": DISPARITY_NOISE}


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
            task = SceneTask(**{**task_kw, "method": method,
                                "depth_model": str(model_path) if source == "estimated" else None,
                                "depth_kind": "inverse"})
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
