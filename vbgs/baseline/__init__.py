"""Gradient 3D Gaussian Splatting baseline: parameters, loss, Adam step, densification
within a fixed capacity, and replay buffers for continual training.

``params_from_prior`` starts from the same place as VBGS (a :func:`vbgs.inference.model.init`
prior); ``Trainer`` runs the jitted step; ``parse_replay`` builds the buffers the
continual protocol uses. The 2-D image variant is in :mod:`vbgs.baseline.image`.
"""

from vbgs.baseline.densify import DEAD_OPACITY, DensifyConfig, relocate
from vbgs.baseline.loss import SSIM_LAMBDA, depth_loss, frame_loss, image_loss
from vbgs.baseline.params import (
    INIT_OPACITY,
    Params,
    colours,
    count_live,
    covariances,
    init_params,
    live,
    opacities,
    params_from_prior,
    params_from_splats,
    to_splats,
    trainable,
)
from vbgs.baseline.replay import Replay, parse_replay
from vbgs.baseline.train import (
    FrameArrays,
    TrainConfig,
    Trainer,
    TrainState,
    camera_extent,
    frame_arrays,
    learning_rates,
    make_optimizer,
    make_step,
    reset_moments,
    seen_rows,
)

__all__ = [
    "DEAD_OPACITY", "INIT_OPACITY", "SSIM_LAMBDA", "DensifyConfig", "FrameArrays", "Params",
    "Replay", "TrainConfig", "TrainState", "Trainer", "camera_extent", "colours", "count_live",
    "covariances", "depth_loss", "frame_arrays", "frame_loss", "image_loss", "init_params",
    "learning_rates", "live", "make_optimizer", "make_step", "opacities", "params_from_prior",
    "params_from_splats", "parse_replay", "relocate", "reset_moments", "seen_rows", "to_splats",
    "trainable",
]
