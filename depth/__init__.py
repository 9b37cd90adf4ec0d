"""Monocular depth for RGB-only input: any ONNX depth model through onnxruntime
(:class:`OnnxDepth`), alignment of relative/inverse predictions to metric depth
(:func:`align`, :func:`apply`), and the ``python -m depth`` CLI."""

from depth.align import (
    METHODS,
    Alignment,
    align,
    apply,
    median_scale,
    scale_shift,
    scale_shift_inverse,
)
from depth.onnx_depth import OnnxDepth
from depth.presets import KINDS, PRESETS, Preset

__all__ = [
    "KINDS",
    "METHODS",
    "PRESETS",
    "Alignment",
    "OnnxDepth",
    "Preset",
    "align",
    "apply",
    "median_scale",
    "scale_shift",
    "scale_shift_inverse",
]
