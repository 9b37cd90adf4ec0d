"""The image task: fit one photo with VBGS (batch CAVI or a patch stream) or with the
gradient baseline, and score it.

The gradient baseline (:func:`run_gradient_image`) fits 2-D Gaussians to the photo
with the 3DGS trainer (normalised render as VBGS's, see :mod:`vbgs.baseline.image`).
It has no CAVI iterations: ``task.iters`` is ignored and ``steps`` (default
``IMAGE_STEPS`` = 2000) is a keyword.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import jax
import numpy as np

from experiments.tasks.init_schemes import oracle_start
from experiments.progress import progress as progress_bar
from experiments.tasks.settings import ASSIGN, INIT, METHOD, ORDER, STREAM
from vbgs.data.images import image_to_points, load_image, patch_stream
from vbgs.inference import grow, model
from vbgs.inference.bound import StreamBound, batch_bound
from vbgs.inference.fit import fit
from vbgs.io_atomic import write_atomic
from vbgs.render.image import render_image
from vbgs.render.metrics import psnr, ssim

if TYPE_CHECKING:  # vbgs.mapping imports the renderer (scipy, skimage): a batch fit needs none
    from vbgs import mapping


@dataclass(frozen=True)
class ImageTask:
    """Everything that defines one image fit."""

    image: str = "astronaut"
    size: int | None = 64
    components: int = 2000
    iters: int = 10
    init: str = INIT.default  # see experiments.tasks.init_schemes
    seed: int = 0
    stream: str = STREAM.default  # none | patches
    order: str = ORDER.default
    assign: str = ASSIGN.default
    patch: int = 8
    reassign: bool = True  # batch fits re-seed unused components (streams: opt-in)
    method: str = METHOD.default  # vbgs | gradient (vbgs-polish: scenes only)
    steps: int = 2000  # gradient baseline only: optimiser steps
    prior: model.PriorConfig = model.PriorConfig()

    def __post_init__(self):
        for name, choice in (("stream", STREAM), ("order", ORDER), ("assign", ASSIGN),
                             ("method", METHOD)):
            choice.check(name, getattr(self, name))
        if not isinstance(self.components, int) or self.components < 1:
            raise ValueError(f"components must be a positive integer, got {self.components!r}")
        if not isinstance(self.iters, int) or self.iters < 1:
            raise ValueError(f"iters must be a positive integer, got {self.iters!r}")
        if self.method == "vbgs-polish":
            raise ValueError("vbgs-polish is a scene learner: fit an image with --method vbgs "
                             "or gradient")
        oracle_start(self.init)  # a known scheme
        if self.init == "stream" and self.stream != "none" and self.reassign:
            raise ValueError("reassign moves unused components, but a stream started with "
                             "init 'stream' grows its own: turn reassign off")


@jax.jit
def task_keys(seed) -> tuple[jax.Array, jax.Array]:
    """The keys of the initialisation and of the fit: ``split(key(seed))``, compiled as
    one function (eager, seeding, splitting and unpacking compile one each)."""
    k_init, k_fit = jax.random.split(jax.random.key(seed))
    return k_init, k_fit


def image_prior(task: ImageTask, uv, rgb, key: jax.Array) -> model.Mixture:
    """The prior of a fit on all pixels ``uv [n, 2]``, ``rgb [n, 3]`` at once (for a batch
    fit the whole image is the first and only batch, so ``stream`` peeks at nothing)."""
    if task.init == "stream":
        return grow.batch_prior(uv, rgb, task.components, key=key, config=task.prior)
    return model.init(uv, rgb, task.components, key=key, scheme=task.init, config=task.prior)


def stream_config(task: ImageTask, first_share: float) -> mapping.Config:
    """The stream loop's config for the task's patch stream (:func:`vbgs.mapping.update_points`):
    the dense E-step over 2-D pixels, no merging. ``init="stream"`` grows from the first
    patch, which gets ``first_share`` of K, and solves each patch by local coordinate
    ascent under posterior assignment (grown components start at their prior); an oracle
    start re-seeds its unused components before each patch under ``reassign``."""
    from vbgs import mapping  # only a stream needs it (start-up of a batch fit)

    growth = mapping.GrowthConfig(first_frame_share=first_share, refine_share=0.0,
                                  merge=False)
    grows = task.init == "stream"
    return mapping.Config(components=task.components, assign=task.assign, estep="dense",
                          prior=task.prior, growth=growth,
                          local_iters=model.LOCAL_MAX_ITERS if grows else 1,
                          reseed=task.reassign)


def stream_patches(task: ImageTask, batches: list, h: int, w: int, k_init: jax.Array,
                   k_fit: jax.Array, uv, rgb, *, progress: bool
                   ) -> tuple[model.State, StreamBound]:
    """One pass over the patches through the stream loop (:func:`stream_config`), with the
    streaming bound (:mod:`vbgs.inference.bound`). ``init="stream"`` grows from the first
    patch, which gets its share of K by pixels (the image's size is the sensor's, known
    before any data); ``data`` and ``random`` start from the whole image ``uv``, ``rgb``
    (an oracle start). With ``reassign`` on, the bound's ``q_{t-1}`` is the posterior
    before the re-seeding (not after)."""
    from vbgs import mapping  # only a stream needs it (start-up of a batch fit)

    shown = progress_bar(batches, desc="patches", unit="patch", enabled=progress)
    config = stream_config(task, len(batches[0][0]) / (h * w))
    if task.init == "stream":
        state = mapping.init(config, key=k_init)
    else:
        state = mapping.init(config, key=k_fit, prior=image_prior(task, uv, rgb, k_init))
    total = StreamBound()
    for xyz, rgb_ in shown:
        previous = None if state.mixture is None else state.mixture.posterior
        state, info = mapping.update_points(state, xyz, rgb_, config)
        before = previous if config.reseed else info.before
        total = total.add(batch_bound(before, state.mixture.posterior, xyz, rgb_,
                                      config=task.prior))
    return state.mixture, total


def task_image(task: ImageTask, image: np.ndarray | None = None, *,
               cache: Path | None = None) -> np.ndarray:
    """The task's target: ``image`` when the caller has loaded it already (the CLI does,
    to check sizes before the fit: loading and resizing twice costs start-up time), else
    ``load_image(task.image, task.size, cache=cache)``."""
    return load_image(task.image, task.size, cache=cache) if image is None else image


def run_image(task: ImageTask, *, progress: bool = False,
              image: np.ndarray | None = None) -> dict:
    """Fit, render and score; returns the metrics, the settings, the ELBO trace and
    (under ``"images"``) the target and render for plotting. ``image``: the target if
    already loaded (``load_image(task.image, task.size)``), see :func:`task_image`."""
    if task.method == "gradient":
        return run_gradient_image(task, progress=progress, steps=task.steps, image=image)
    img = task_image(task, image)
    h, w, _ = img.shape
    uv, rgb = image_to_points(img)
    k_init, k_fit = task_keys(task.seed)
    start = time.perf_counter()
    if task.stream == "none":
        prior = image_prior(task, uv, rgb, k_init)
        # one compiled function for all iterations (no per-iteration progress: a
        # callback would run them one by one from the host)
        post, info = fit(prior, uv, rgb, iters=task.iters, config=task.prior,
                         key=k_fit if task.reassign else None)
        elbo, counts = info.elbo, np.asarray(post.alpha) - np.asarray(prior.alpha)  # host
        extra = {}
    else:
        batches = list(patch_stream(img, task.patch, task.order, seed=task.seed))
        state, bound = stream_patches(task, batches, h, w, k_init, k_fit, uv, rgb,
                                      progress=progress)
        # a stream has no ELBO of one data set: its objective is the streaming bound
        post, elbo, counts = state.posterior, np.zeros(0), state.stats.count
        extra = bound.summary()
    render = render_image(post, h, w)
    seconds = time.perf_counter() - start
    settings = asdict(task)
    settings.pop("prior")
    return {
        **settings,
        "oracle_start": task.stream != "none" and oracle_start(task.init),
        "height": h,
        "width": w,
        "psnr": psnr(render, img),
        "ssim": ssim(render, img),
        "seconds": seconds,
        "components_used": int(model.used_components(np.asarray(counts)).sum()),
        "elbo": [float(e) for e in elbo],
        **extra,
        "images": {"target": img, "render": render},
    }


def run_gradient_image(task: ImageTask, *, steps: int | None = None, progress: bool = False,
                       config=None, image: np.ndarray | None = None) -> dict:
    """Fit 2-D Gaussians to the task's image with Adam for ``steps`` steps (``task.iters``
    is ignored); same keys as :func:`experiments.tasks.image_task.run_image`, with the loss
    trace under ``"loss"`` and ``"elbo": []``. ``config``: a
    :class:`vbgs.baseline.TrainConfig` (its defaults, the position rate decaying over
    :data:`vbgs.baseline.image.IMAGE_LR_DECAY_STEPS` steps, when None); ``image`` as for
    :func:`run_image`."""
    from vbgs.baseline.image import IMAGE_STEPS

    steps = IMAGE_STEPS if steps is None else steps
    if not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    (record,) = gradient_image_path(task, (steps,), progress=progress, config=config,
                                    image=image)
    return record


def gradient_image_path(task: ImageTask, checkpoints, *, progress: bool = False, config=None,
                        image: np.ndarray | None = None):
    """One Adam fit of the task's image to the largest of ``checkpoints`` (step counts),
    yielding at each the record :func:`run_gradient_image` gives for that many steps (the
    schedule is per step, :func:`vbgs.baseline.image.fit_image_path`); ``seconds`` is
    the training to that count and its render (as a run of that length times itself),
    cumulative, the renders and scores at the earlier checkpoints left out."""
    from vbgs.baseline import TrainConfig, count_live, params_from_prior
    from vbgs.baseline.densify import DEAD_OPACITY
    from vbgs.baseline.image import IMAGE_LR_DECAY_STEPS, fit_image_path, render_image_params

    counts = sorted({int(n) for n in checkpoints})
    img = task_image(task, image)
    h, w, _ = img.shape
    uv, rgb = image_to_points(img)
    k_init, k_fit = task_keys(task.seed)  # as run_image splits
    prior = image_prior(task, uv, rgb, k_init)
    bar = progress_bar(total=counts[-1], desc="Adam", unit="step", enabled=progress)
    start = time.perf_counter()
    config = config or TrainConfig(lr_decay_steps=IMAGE_LR_DECAY_STEPS)  # images: no depth
    path = fit_image_path(params_from_prior(prior), img, checkpoints=counts, config=config,
                          key=k_fit, callback=lambda n: bar.update(n - bar.n))
    scoring = 0.0  # seconds spent rendering and scoring earlier checkpoints
    settings = asdict(task)
    settings.pop("prior")
    for steps, params, losses in path:
        t0 = time.perf_counter()
        render = np.clip(np.asarray(render_image_params(params, h, w)), 0.0, 1.0)
        seconds = time.perf_counter() - start - scoring  # this checkpoint's render counted
        record = {
            **settings,
            "method": "gradient",
            "steps": steps,
            "height": h,
            "width": w,
            "psnr": psnr(render, img),
            "ssim": ssim(render, img),
            "seconds": seconds,
            "components_used": count_live(params, DEAD_OPACITY),
            "elbo": [],
            "loss": [float(x) for x in losses],
            "images": {"target": img, "render": render},
        }
        scoring += time.perf_counter() - t0
        yield record
    bar.close()


def save_comparison(path: str | Path, target: np.ndarray, render: np.ndarray, title: str) -> None:
    """Target, render and absolute error side by side in one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    err = np.abs(render - target).mean(-1)
    fig, axes = plt.subplots(1, 3, figsize=(10, 3.6))
    for ax, im, name in zip(axes, (target, render, err), ("target", "render", "|error|"),
                            strict=True):
        shown = ax.imshow(im, cmap="magma" if im.ndim == 2 else None,
                          vmin=0, vmax=max(float(err.max()), 1e-6) if im.ndim == 2 else None)
        ax.set_title(name)
        ax.axis("off")
    fig.colorbar(shown, ax=axes[2], fraction=0.046, label="mean abs error (colour units)")
    fig.suptitle(title)
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=120, bbox_inches="tight"))
    plt.close(fig)
