"""Diagnostic: how much of the gap to the gradient baseline is the picture, how much the
geometry (``python -m experiments.run render-bound``).

The VBGS learner streams the scene once; its final splats are then refined by Adam on
the gradient baseline's loss (L1 + SSIM, plus its depth term: :mod:`vbgs.baseline.loss`)
over every training frame, ``steps`` steps on frames drawn uniformly, three ways:

* ``colours``: the colours only, everything else frozen;
* ``colours_opacities``: colours and opacities, the means and covariances frozen: the
  best that any rule turning VBGS's geometry into colour and opacity could reach (the
  colour fit of :mod:`vbgs.render.colour_fit` and the opacity of :mod:`vbgs.render.opacity` are such
  rules);
* ``everything``: means, scales and rotations too, from VBGS's splats.

Each is scored on the held-out test views beside the learner's own splats. The
refinements read every training frame again, so they are yardsticks, never a
learner's method, and nothing is tuned here: the test views only report. Learning rates
are the baseline's (3DGS's, :class:`vbgs.baseline.TrainConfig`) on its per-step schedule
(the position rate decays over
:data:`experiments.learners.gradient_learner.SCENE_LR_DECAY_STEPS` steps, whatever
``steps`` is: a refinement of N steps is the first N of a longer one,
:func:`refine_path`); splats are drawn with the VBGS learner's pixel filter throughout.
"""

from __future__ import annotations

import time
from dataclasses import replace

import jax.numpy as jnp
import numpy as np

from experiments.learners.gradient_learner import DEFAULT_CONFIG
from experiments.studies.tune import learn_once
from vbgs.baseline import camera_extent, frame_arrays, params_from_splats, trainable
from vbgs.baseline.params import Params, to_splats
from vbgs.baseline.train import make_optimizer, make_step
from vbgs.render.raster import exact_capacity
from vbgs.render.splats import Splats
from vbgs.render.views import evaluate

# What each refinement trains (Params fields); the rest keep VBGS's values.
REFINED = {
    "colours": ("colour_logits",),
    "colours_opacities": ("colour_logits", "opacity_logits"),
    "everything": ("colour_logits", "opacity_logits", "means", "log_scales", "rotations"),
}
def refine_path(splats: Splats, frames: list, background, *, what: str, steps, blur: float,
                extent: float, seed: int = 0) -> dict[int, Splats]:
    """``splats`` refining ``what`` (a key of :data:`REFINED`) by Adam on ``frames`` (one
    drawn uniformly a step), after each step count of ``steps`` (one run to the largest:
    the schedule and the draws are per step, so each is what a run of that length gives)."""
    counts = sorted(set(int(n) for n in steps))
    if not counts or counts[0] < 1:
        raise ValueError(f"steps must be positive integers, got {steps!r}")
    capacity = max(exact_capacity(splats, f.camera, blur=blur) for f in frames)
    capacity = 1 << int(np.ceil(np.log2(max(capacity, 1))))  # a power of two: one compile
    config = replace(DEFAULT_CONFIG, raster_capacity=capacity, blur=blur)
    optimizer = make_optimizer(config, extent)
    step = make_step(config, optimizer, frozen=tuple(f for f in Params._fields[:-1]
                                                     if f not in REFINED[what]))
    params = params_from_splats(splats)
    opt_state = optimizer.init(trainable(params))
    arrays = [frame_arrays(f) for f in frames]
    bg = jnp.asarray(background, jnp.float32)
    # Generator.integers draws one after another: the first N of a longer draw are its own
    picks = np.random.default_rng(seed).integers(0, len(arrays), counts[-1])
    out = {}
    for t, i in enumerate(picks, 1):
        params, opt_state, _ = step(params, opt_state, *arrays[int(i)], bg)
        if t in counts:
            out[t] = to_splats(params)
    return out


def refine(splats: Splats, frames: list, background, *, what: str, steps: int, blur: float,
           extent: float, seed: int = 0) -> Splats:
    """``splats`` after ``steps`` Adam steps on ``frames`` refining ``what`` (a key of
    :data:`REFINED`; :func:`refine_path` at one step count)."""
    return refine_path(splats, frames, background, what=what, steps=(steps,), blur=blur,
                       extent=extent, seed=seed)[steps]


def render_bound(task, scene, *, steps: int = 900, progress: bool = False) -> dict:
    """Held-out PSNR/SSIM of the learner's splats and of each refinement (module
    docstring), with the seconds each refinement took."""
    learner, background = learn_once(task, scene, progress=progress)
    splats = learner.splats(drop_unused=True)
    extent = camera_extent([f.camera.position for f in scene.train])
    ev = evaluate(splats, scene.test, background, learner.blur)
    out = {"steps": steps, "vbgs_psnr": ev.psnr, "vbgs_ssim": ev.ssim}
    for what in REFINED:
        start = time.perf_counter()
        refined = refine(splats, scene.train, background, what=what, steps=steps,
                         blur=learner.blur, extent=extent, seed=task.seed)
        out[f"{what}_seconds"] = time.perf_counter() - start
        ev = evaluate(refined, scene.test, background, learner.blur)
        out[f"{what}_psnr"], out[f"{what}_ssim"] = ev.psnr, ev.ssim
    return out
