"""Diagnostic: the streamed colour fit against exact least squares (``python -m
experiments.run colour-gap``).

The VBGS learner streams the scene once under ``colour_rule="fit"``; its final splats
are then coloured four ways and scored on the held-out views:

* ``posterior``: the posterior colour means (``colour_rule="posterior"``);
* ``lumped_stream``: the shipped rule, the lumped normal equations summed along the
  stream, each frame's weights rendered from the posterior just after it;
* ``lumped_final``: the same lumped solve, every training frame re-rendered with the
  final splats (separates the lumping from the frames' older geometry);
* ``exact``: the full least squares over every training frame rendered with the final
  splats, solved by conjugate gradients (:func:`vbgs.render.colour_fit.exact_colours`). It
  needs every frame again, so it is a yardstick only, never a learner's method.

Nothing is tuned here: the test views only report.
"""

from __future__ import annotations

import time
from dataclasses import replace

import jax.numpy as jnp

from experiments.studies.tune import learn_once
from vbgs import mapping
from vbgs.render import colour_fit
from vbgs.render.views import evaluate


def colour_gap(task, scene, *, iterations: int = 30, progress: bool = False) -> dict:
    """Held-out PSNR/SSIM of each colouring (module docstring, all with the task's
    ``colour_ridge``), the CG iterations run and the seconds the exact solve took."""
    learner, background = learn_once(replace(task, colour_rule="fit"), scene,
                                     progress=progress)
    posterior_colours = mapping.with_dotted(learner.config, "render.colour_rule", "posterior")
    base = mapping.splats(learner.state, posterior_colours)  # [k] with the posterior colours
    c_post = learner.state.mixture.posterior.colour.mean  # [k, 3]
    final = colour_fit.no_frames(base.count)
    for frame in scene.train:
        final = colour_fit.observe(final, base, frame.camera, frame.rgb, background,
                                   blur=learner.blur)
    start = time.perf_counter()
    ridge = task.colour_ridge
    exact, iters = colour_fit.exact_colours(base, scene.train, background, c_post, ridge=ridge,
                                            iterations=iterations, blur=learner.blur)
    exact_seconds = time.perf_counter() - start
    colourings = {
        "posterior": c_post,
        "lumped_stream": colour_fit.solve(learner.state.colour, c_post, ridge),
        "lumped_final": colour_fit.solve(final, c_post, ridge),
        "exact": jnp.clip(exact, 0.0, 1.0),
    }
    out = {"cg_iterations": iters, "exact_seconds": exact_seconds}
    for name, colours in colourings.items():
        ev = evaluate(base._replace(colours=jnp.asarray(colours, jnp.float32)), scene.test,
                      background, learner.blur)
        out[f"{name}_psnr"], out[f"{name}_ssim"] = ev.psnr, ev.ssim
    out["gap_db"] = out["exact_psnr"] - out["lumped_stream_psnr"]
    return out
