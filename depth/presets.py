"""Preprocessing presets for common families of monocular depth networks.

A preset says how a family's exports expect their input and what their output
means. Any field can be overridden in :class:`depth.OnnxDepth`; fixed spatial sizes
declared by the ONNX graph itself always win over a preset's ``input_size``.

Normalisation (applied to RGB in [0, 1], per channel c)::

    x_c = (rgb_c - mean_c) / std_c

Input size: with ``keep_aspect`` the shorter frame side is scaled to ``input_size``
and the longer one by the same factor; without it the input is ``input_size``
square. Each side is then rounded to the nearest multiple of ``multiple_of``
(at least one multiple).

Output kinds:

- ``"metric"``: depth in scene units (metres), usable as is.
- ``"inverse"``: relative disparity, ``p = a / depth + b`` for unknown ``a > 0, b``
  per image (Depth Anything, MiDaS, DPT); align with ``scale-shift-inverse``.
- ``"relative"``: affine-invariant depth, ``p = (depth - b) / a``; align with
  ``scale-shift``.
"""

from __future__ import annotations

from dataclasses import dataclass

KINDS = ("metric", "inverse", "relative")

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
HALF = (0.5, 0.5, 0.5)  # DPT-style normalisation to [-1, 1]
NO_MEAN = (0.0, 0.0, 0.0)
NO_STD = (1.0, 1.0, 1.0)

DEPTH_ANYTHING_SIZE = 518  # ViT-14 patches: 37 * 14
DEPTH_ANYTHING_MULTIPLE = 14
MIDAS_SIZE = 384
MIDAS_MULTIPLE = 32
DPT_SIZE = 384


@dataclass(frozen=True)
class Preset:
    """How one model family wants its input and what its output is.

    ``input_size`` None means "the frame's own size" (rounded to ``multiple_of``)
    unless the graph fixes its input size.
    """

    input_size: int | None
    multiple_of: int
    mean: tuple[float, float, float]
    std: tuple[float, float, float]
    kind: str
    keep_aspect: bool
    note: str = ""


PRESETS: dict[str, Preset] = {
    "depth-anything": Preset(
        DEPTH_ANYTHING_SIZE, DEPTH_ANYTHING_MULTIPLE, IMAGENET_MEAN, IMAGENET_STD, "inverse", True,
        "Depth Anything v1/v2 relative exports: disparity up to scale and shift",
    ),
    "midas": Preset(
        MIDAS_SIZE, MIDAS_MULTIPLE, IMAGENET_MEAN, IMAGENET_STD, "inverse", True,
        "MiDaS v2.1/v3 exports: relative inverse depth",
    ),
    "dpt": Preset(
        DPT_SIZE, MIDAS_MULTIPLE, HALF, HALF, "inverse", False,
        "DPT (Hugging Face DPTForDepthEstimation) exports: relative inverse depth",
    ),
    "metric": Preset(
        None, 1, NO_MEAN, NO_STD, "metric", True,
        "a model that takes raw RGB in [0, 1] and returns metric depth",
    ),
}


def get_preset(name: str | None) -> Preset | None:
    """Return the preset called ``name`` (None passes through); refuse unknown names."""
    if name is None:
        return None
    if name not in PRESETS:
        raise ValueError(f"unknown depth preset {name!r}; choose one of {sorted(PRESETS)}")
    return PRESETS[name]


def check_kind(kind: str) -> str:
    """Refuse an unknown output kind with the list of known ones."""
    if kind not in KINDS:
        raise ValueError(f"unknown depth kind {kind!r}; choose one of {KINDS}")
    return kind
