"""2-D gradient baseline: fit normalised 2-D Gaussians to one image with Adam.

The render is normalised the way VBGS renders images (:mod:`vbgs.render.image`):

    Î(x) = Σ_k w_k(x) c_k / Σ_k w_k(x),   w_k(x) = o_k N(x | μ_k, Σ_k),

i.e. ``softmax_k(log o_k + log N(x | μ_k, Σ_k)) @ c`` at pixel centres x (pixel units,
``(u, v) = (col + 0.5, row + 0.5)``). ``log w_k(x)`` is a quadratic in x: features
``φ(x) = [u², uv, v², u, v, 1]`` (coordinates centred on the image middle for float32
precision) dotted with per-splat coefficients.

Speed: a dense render costs O(pixels · K) per step (8M exponentials for 64x64 and
2000 splats, twice for the gradient). The training step instead sums over each
pixel's CANDIDATES splats of largest weight, found by a chunked dense pass every
REFRESH_EVERY steps (:func:`candidates`); the weight left outside them is negligible,
and :func:`render_dense` stays as the obvious reference the tests hold it to.
The loss, optimiser (learning rates relative to ``extent = max(h, w)`` pixels),
densification and training loop are those of the 3-D baseline.
"""

from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import optax

from vbgs.baseline.loss import image_loss
from vbgs.baseline.params import Params, colours, rotation_matrices, trainable
from vbgs.baseline.train import TrainConfig, Trainer
from vbgs.inference.precision import mat_vec, matmul
from vbgs.render.pixels import pixel_centres

IMAGE_STEPS = 2000  # default number of Adam steps for an image fit
# Steps over which the position rate decays 100-fold: a constant of the schedule, never
# the run's length (a run of N steps is the first N of a longer one). The default fit's
# length, so a default fit keeps the schedule it had when the decay spanned the run.
IMAGE_LR_DECAY_STEPS = IMAGE_STEPS
PIXEL_CHUNK = 1024  # pixels per chunk of the dense candidate pass (bounds [chunk, K] blocks)
CANDIDATES = 16  # splats kept per pixel: those of largest weight w_k(x)
REFRESH_EVERY = 25  # steps between candidate refreshes (a dense pass)
INACTIVE_LOG_WEIGHT = -1e30  # log w of inactive rows: no weight, finite arithmetic


def quadratic_coefficients(params: Params) -> jax.Array:
    """``W [K, 6]`` with ``log o_k + log N(x | μ_k, Σ_k) = φ(x) · W_k`` for
    ``φ(x) = [u², uv, v², u, v, 1]`` (x in the same centred frame as the means).

    The precision comes straight from the factors, ``P = Σ⁻¹ = R diag(s⁻²) Rᵀ =
    [[a, b], [b, c]]`` and ``log|Σ| = 2 Σ_i log s_i``; then ``-½(x-μ)ᵀP(x-μ) =
    -½a u² - b uv - ½c v² + (Pμ)·x - ½μᵀPμ``, plus ``log o - log 2π - ½ log|Σ|``.
    P is a full float32 product (:func:`vbgs.inference.precision.matmul`), Pμ an elementwise sum.
    """
    rot = rotation_matrices(params)  # [K, 2, 2]
    prec = matmul(rot * jnp.exp(-2.0 * params.log_scales)[:, None, :], jnp.swapaxes(rot, -1, -2))
    a, b, c = prec[:, 0, 0], prec[:, 0, 1], prec[:, 1, 1]
    lin = mat_vec(prec, params.means)  # [K, 2]
    log_o = jax.nn.log_sigmoid(params.opacity_logits)
    const = (log_o - math.log(2 * math.pi) - jnp.sum(params.log_scales, -1)
             - 0.5 * jnp.sum(lin * params.means, -1))
    const = jnp.where(params.active, const, INACTIVE_LOG_WEIGHT)
    return jnp.stack([-0.5 * a, -b, -0.5 * c, lin[:, 0], lin[:, 1], const], -1)


def pixel_features(xy: jax.Array) -> jax.Array:
    """``φ(x) = [u², uv, v², u, v, 1]`` ``[p, 6]`` of positions ``xy [p, 2]``."""
    u, v = xy[:, 0], xy[:, 1]
    return jnp.stack([u * u, u * v, v * v, u, v, jnp.ones_like(u)], -1)


def dense_logits(params: Params, xy: jax.Array) -> jax.Array:
    """``log w_k(x)`` ``[p, K]`` for every position ``xy [p, 2]`` and every splat: ``φ(x) · W_k``
    at full float32 precision (:func:`vbgs.inference.precision.matmul`). Its terms (u² ~ 10⁴ px² at
    256 px) are far larger than their sum, which TF32 operands would not survive."""
    return matmul(pixel_features(xy), quadratic_coefficients(params).T)


def render_dense(params: Params, xy: jax.Array) -> jax.Array:
    """The slow, obvious render: ``softmax_k(log w_k(x)) @ c`` over all K splats, ``[p, 3]``.
    O(p · K) memory; the reference for :func:`render_sparse`."""
    return matmul(jax.nn.softmax(dense_logits(params, xy), axis=-1), colours(params))


@partial(jax.jit, static_argnames=("n", "chunk"))
def candidates(params: Params, xy: jax.Array, n: int = CANDIDATES,
               chunk: int = PIXEL_CHUNK) -> jax.Array:
    """Indices ``[p, n]`` of the n splats of largest ``w_k(x)`` at each position (a dense
    pass in chunks of ``chunk`` positions; p must be a multiple of ``chunk`` or smaller)."""
    params = jax.lax.stop_gradient(params)
    chunk = min(chunk, xy.shape[0])
    if xy.shape[0] % chunk:
        raise ValueError(f"{xy.shape[0]} positions are not a multiple of the chunk {chunk}")
    n = min(n, params.capacity)

    def one_chunk(xb):  # [c, 2] -> [c, n]
        return jax.lax.top_k(dense_logits(params, xb), n)[1]

    return jax.lax.map(one_chunk, xy.reshape(-1, chunk, 2)).reshape(-1, n)


def render_sparse(params: Params, xy: jax.Array, cand: jax.Array) -> jax.Array:
    """``softmax_{k ∈ cand(x)}(log w_k(x)) @ c`` ``[p, 3]``: the normalised render restricted
    to each position's candidates ``cand [p, n]`` (see :func:`candidates`). Differentiable
    w.r.t. ``params``; equals :func:`render_dense` when the weight outside the candidates
    is negligible."""
    # One scalar gather per coefficient: measured 2x faster on CPU than gathering
    # [p, n, 6] rows (and einsum becomes p tiny batched matmuls).
    weights = quadratic_coefficients(params)  # [K, 6]
    phi = pixel_features(xy)  # [p, 6]
    logits = sum(phi[:, f, None] * weights[:, f][cand] for f in range(phi.shape[1]))  # [p, n]
    resp = jax.nn.softmax(logits, axis=-1)
    cols = colours(params)  # [K, 3]
    return jnp.stack([jnp.sum(resp * cols[:, j][cand], axis=1) for j in range(3)], -1)


def image_centre(height: int, width: int) -> np.ndarray:
    """The centre ``(w / 2, h / 2)`` of the image, the origin of the fitting frame."""
    return np.array([width / 2.0, height / 2.0], np.float32)


def centred_pixels(height: int, width: int) -> jax.Array:
    """Pixel centres ``[h * w, 2]`` (row-major) relative to :func:`image_centre`."""
    return jnp.asarray(pixel_centres(height, width) - image_centre(height, width))


def centred(params: Params, height: int, width: int) -> Params:
    """Params with means moved into the centred frame of :func:`centred_pixels`."""
    return params._replace(means=params.means - jnp.asarray(image_centre(height, width)))


def image_candidates(params: Params, height: int, width: int, n: int = CANDIDATES) -> jax.Array:
    """:func:`candidates` ``[h * w, n]`` of every pixel of an ``h x w`` image."""
    xy = centred_pixels(height, width)
    return candidates(centred(params, height, width), xy, n, math.gcd(xy.shape[0], PIXEL_CHUNK))


def render_image_params(params: Params, height: int, width: int, cand=None) -> jax.Array:
    """Render params (means in pixel units) to an image ``[h, w, 3]``; ``cand`` are the
    pixels' candidates (computed here when None)."""
    if cand is None:
        cand = image_candidates(params, height, width)
    xy = centred_pixels(height, width)
    return render_sparse(centred(params, height, width), xy, cand).reshape(height, width, 3)


def make_image_step(config: TrainConfig, optimizer):
    """The jitted ``step(params, opt_state, target [h, w, 3], cand [h*w, n]) ->
    (params, opt_state, loss)``."""

    def loss_fn(theta, active, target, cand):
        h, w = target.shape[:2]
        render = render_image_params(theta._replace(active=active), h, w, cand)
        return image_loss(render, target, config.ssim_weight)

    @jax.jit
    def step(params: Params, opt_state, target, cand):
        theta = trainable(params)
        loss, grads = jax.value_and_grad(loss_fn)(theta, params.active, target, cand)
        updates, opt_state = optimizer.update(grads, opt_state, theta)
        return optax.apply_updates(theta, updates)._replace(active=params.active), opt_state, loss

    return step


def fit_image_path(params: Params, image, *, checkpoints, config: TrainConfig | None = None,
                   key: jax.Array, callback=None):
    """Fit 2-D ``params`` (means in pixels) to ``image [h, w, 3]`` by Adam, one run to the
    largest of ``checkpoints`` (step counts), yielding ``(steps, params, losses [steps])``
    at each. Candidates are refreshed every REFRESH_EVERY steps counted from the start
    (and so right after every densification, whose interval is a multiple of it by
    default), whatever the checkpoints; with the per-step schedule (``config`` defaults to
    :class:`TrainConfig` with ``lr_decay_steps = IMAGE_LR_DECAY_STEPS``) each checkpoint
    is what a run of that many steps gives. ``callback(n_done)`` after each block. The
    caller's time between yields is the training's alone."""
    if params.dim != 2:
        raise ValueError(f"fit_image needs 2-D params, got {params.dim}-D")
    counts = sorted({int(n) for n in checkpoints})
    if not counts or counts[0] < 1:
        raise ValueError(f"checkpoints must be positive step counts, got {checkpoints!r}")
    config = config or TrainConfig(lr_decay_steps=IMAGE_LR_DECAY_STEPS)
    h, w = image.shape[:2]
    trainer = Trainer(config, extent=float(max(h, w)), make_step_fn=make_image_step)
    state = trainer.init(params, key=key)
    target = jnp.asarray(image, jnp.float32)
    losses, done, cand = [], 0, None
    for goal in counts:
        while done < goal:
            if done % REFRESH_EVERY == 0:
                cand = image_candidates(state.params, h, w)
            n = min(REFRESH_EVERY - done % REFRESH_EVERY, goal - done)
            state, block = trainer.train(state, [(target, cand)], n)
            losses.append(block)
            done += n
            if callback is not None:
                callback(done)
        yield goal, state.params, np.concatenate(losses)


def fit_image(params: Params, image, *, steps: int = IMAGE_STEPS,
              config: TrainConfig | None = None, key: jax.Array, callback=None):
    """Fit 2-D ``params`` (means in pixels) to ``image [h, w, 3]`` for ``steps`` Adam steps
    (:func:`fit_image_path` to one checkpoint). Returns the fitted params and the loss per
    step ``[steps]``."""
    (_, params, losses), = fit_image_path(params, image, checkpoints=(steps,), config=config,
                                          key=key, callback=callback)
    return params, losses
