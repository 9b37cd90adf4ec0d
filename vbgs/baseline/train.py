"""Optimiser, jitted training step and training loop of the gradient 3DGS baseline.

Adam (``eps = 1e-15`` as in 3DGS) followed by a per-parameter learning rate, the 3DGS
defaults:

    means        1.6e-4 · extent, decaying exponentially to 1.6e-6 · extent:
                 lr(t) = lr_0 (lr_1 / lr_0)^(min(t, T) / T),  T = lr_decay_steps
    colours      2.5e-3 (3DGS's feature rate, here on colour logits, see params.py)
    opacities    5e-2 (on logits)
    scales       5e-3 (on log-scales)
    rotations    1e-3 (on quaternions)

``extent`` is the scene size that makes the position rate unit-free; for scenes use
:func:`camera_extent` (3DGS: 1.1 × the largest distance of a camera centre from their
mean). The schedule is a function of the step alone: ``T`` is a constant of the config
(3DGS: 30k steps), never the length of the run, which a continual learner cannot know.
The step count ``t`` is the optimiser state's (a traced array), so one compiled step
serves runs of every length.

The step takes the frame and its camera as arrays (``rgb, depth, fx, fy, cx, cy,
pose``): only the image size is static, so one compiled step serves every frame of a
scene (check with ``step._cache_size()``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from vbgs.baseline.densify import DensifyConfig, relocate
from vbgs.baseline.loss import SSIM_LAMBDA, frame_loss
from vbgs.baseline.params import Params, to_splats, trainable
from vbgs.render.camera import Camera
from vbgs.render.raster import BLUR_VARIANCE, DEFAULT_CAPACITY, DEFAULT_TILE, rasterize

CAMERA_EXTENT_MARGIN = 1.1  # 3DGS enlarges the camera radius by 10%
ADAM_EPS = 1e-15  # 3DGS's Adam epsilon
STEP_CACHE_SIZE = 8  # compiled steps kept for reuse by later trainers
ADAM, LEARNING_RATES = "adam", "learning_rates"  # stage names of the optimiser state


@dataclass(frozen=True)
class TrainConfig:
    """Hyperparameters of the baseline trainer (3DGS defaults; see the module docstring)."""

    # × extent; 3DGS's, confirmed for scenes on validation views: results/tuning/baseline-lr
    # (mean.md, the code version in its first line: a doubled rate scores 26.02 dB mean
    # against 25.99, within 0.1 dB of mean PSNR, so 3DGS's value is kept)
    lr_means: float = 1.6e-4
    lr_means_final: float = 1.6e-6  # × extent
    lr_decay_steps: int = 30_000
    lr_colours: float = 2.5e-3
    lr_opacity: float = 5e-2
    lr_scales: float = 5e-3
    lr_rotations: float = 1e-3
    adam_eps: float = ADAM_EPS
    ssim_weight: float = SSIM_LAMBDA
    depth_weight: float = 0.0  # weight of the masked depth L1 (0: RGB only, as 3DGS)
    densify: DensifyConfig | None = field(default_factory=DensifyConfig)  # None: off
    tile: int = DEFAULT_TILE
    raster_capacity: int = DEFAULT_CAPACITY
    blur: float = BLUR_VARIANCE  # px², the pixel filter the splats are rendered with

    def __post_init__(self):
        if self.lr_decay_steps < 1:
            raise ValueError(f"lr_decay_steps must be >= 1, got {self.lr_decay_steps}")


def camera_extent(positions) -> float:
    """3DGS's scene extent: 1.1 × max distance of camera centres ``[n, 3]`` from their mean
    (1.1 when there is a single camera)."""
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    radius = float(np.linalg.norm(pos - pos.mean(0), axis=1).max(initial=0.0))
    return CAMERA_EXTENT_MARGIN * (radius if radius > 0 else 1.0)


def learning_rates(config: TrainConfig, extent: float) -> Params:
    """Per-parameter learning rates (schedules of the step count), shaped like Params."""
    means = optax.exponential_decay(
        init_value=config.lr_means * extent, transition_steps=config.lr_decay_steps,
        decay_rate=config.lr_means_final / config.lr_means,
        end_value=config.lr_means_final * extent,
    )
    return Params(means, config.lr_scales, config.lr_rotations, config.lr_opacity,
                  config.lr_colours, None)


class LearningRateState(NamedTuple):
    count: jax.Array  # [] int32 steps taken


def scale_by_learning_rates(rates: Params) -> optax.GradientTransformation:
    """``u_leaf <- -lr_leaf(t) · u_leaf`` with a float or schedule per Params field."""

    def init(_params):
        return LearningRateState(jnp.zeros((), jnp.int32))

    def update(updates, state, params=None):
        del params

        def scale(u, lr):
            return -(lr(state.count) if callable(lr) else lr) * u

        return jax.tree.map(scale, updates, rates), LearningRateState(state.count + 1)

    return optax.GradientTransformation(init, update)


def make_optimizer(config: TrainConfig, extent: float) -> optax.GradientTransformation:
    """Adam with the per-parameter 3DGS learning rates, over :func:`trainable` params.

    Its state is a dict by stage name: ``opt_state[ADAM]`` holds Adam's moments."""
    rates = scale_by_learning_rates(learning_rates(config, extent))
    return optax.named_chain((ADAM, optax.scale_by_adam(eps=config.adam_eps)),
                             (LEARNING_RATES, rates))


def _rows_where(rows: jax.Array, a, b):
    """Per row of every leaf: ``a`` where ``rows [K]`` (bool), else ``b`` (equal pytrees)."""
    return jax.tree.map(lambda x, y: jnp.where(rows.reshape((-1,) + (1,) * (x.ndim - 1)), x, y),
                        a, b)


def _with_moments(opt_state, mu, nu):
    out = opt_state.copy()  # the same mapping type (an OrderedDict): the same pytree structure
    out[ADAM] = opt_state[ADAM]._replace(mu=mu, nu=nu)
    return out


def reset_moments(opt_state, rows: jax.Array):
    """Zero Adam's first and second moments of the rows ``rows [K]`` (bool)."""
    adam = opt_state[ADAM]
    zeros = functools.partial(jax.tree.map, jnp.zeros_like)
    return _with_moments(opt_state, _rows_where(rows, zeros(adam.mu), adam.mu),
                         _rows_where(rows, zeros(adam.nu), adam.nu))


def seen_rows(grads: Params) -> jax.Array:
    """``[K]`` bool: the rows with any nonzero gradient (the splats a frame's picture
    depends on; a splat outside the view, or culled, gets exactly 0)."""
    leaves = [jnp.abs(x).reshape(x.shape[0], -1).max(-1) for x in jax.tree.leaves(grads)]
    return jnp.stack(leaves).max(0) > 0


def keep_rows(new_state, old_state, rows: jax.Array):
    """``new_state``'s Adam moments on the rows ``rows [K]`` (bool), ``old_state``'s
    elsewhere (the step counts are ``new_state``'s: the schedule is the run's)."""
    new, old = new_state[ADAM], old_state[ADAM]
    return _with_moments(new_state, _rows_where(rows, new.mu, old.mu),
                         _rows_where(rows, new.nu, old.nu))


def gradient_score(opt_state) -> jax.Array:
    """``sqrt(Σ_d ν_means)`` per row ``[K]``: Adam's running RMS of the position gradient."""
    return jnp.sqrt(jnp.sum(opt_state[ADAM].nu.means, axis=-1))


class FrameArrays(NamedTuple):
    """A frame as the step consumes it: device arrays, float32, and its camera (a pytree
    whose width and height are static)."""

    rgb: jax.Array  # [h, w, 3]
    depth: jax.Array  # [h, w] 0 = invalid
    camera: Camera  # intrinsics [] each and pose [4, 4] as float32 arrays
    pixel_weight: jax.Array | None = None  # [h, w] the depth term's weights (measured
    #                                        depth, vbgs.baseline.loss); None: exact


def frame_arrays(frame, pixel_weight=None) -> FrameArrays:
    """A :class:`vbgs.data.scene.Frame` (rgb, depth, camera) as :class:`FrameArrays`, with
    the depth term's ``pixel_weight [h, w]`` when its depth was measured."""
    if isinstance(frame, FrameArrays):
        return frame
    cam = frame.camera
    f32 = jnp.float32
    camera = cam._replace(**{k: jnp.asarray(getattr(cam, k), f32)
                             for k in ("fx", "fy", "cx", "cy", "pose")})
    weight = None if pixel_weight is None else jnp.asarray(pixel_weight, f32)
    return FrameArrays(jnp.asarray(frame.rgb, f32), jnp.asarray(frame.depth, f32), camera,
                       weight)


def make_step(config: TrainConfig, optimizer: optax.GradientTransformation, *, on_trace=None,
              frozen: tuple[str, ...] = (), penalty=None, seen_only: bool = False):
    """The jitted ``step(params, opt_state, rgb, depth, camera, pixel_weight, background)
    -> (params, opt_state, loss)`` (``*frame_arrays(frame)`` gives rgb, depth, camera and
    the depth term's pixel weights, None for exact depth):
    render over ``background [3]`` (an argument, so a background that is re-estimated
    as frames arrive costs no recompile), :func:`vbgs.baseline.loss.frame_loss`, one
    optimiser update; one compile per image size (the camera's static width and
    height). ``on_trace()`` (optional) is called each time it is traced. ``frozen``
    names Params fields whose gradients are zeroed, so Adam leaves them where they are.
    ``penalty(theta, *extra) -> scalar`` (optional) is added to the loss, ``extra`` being
    the step's arguments after ``background`` (e.g. the anchor of
    :mod:`vbgs.baseline.anchor`); the returned loss includes it. ``seen_only``: the
    step moves only the rows the frame's picture depends on (:func:`seen_rows` of the
    photometric gradient); the others, and their Adam moments, stay as they are, penalty
    or not (the polish's rule, :mod:`experiments.learners.polish_learner`)."""

    def photometric(theta: Params, active, rgb, depth, camera: Camera, pixel_weight,
                    background):
        out = rasterize(to_splats(theta._replace(active=active)), camera, background=background,
                        tile=config.tile, capacity=config.raster_capacity, blur=config.blur)
        return frame_loss(out, rgb, depth, ssim_weight=config.ssim_weight,
                          depth_weight=config.depth_weight, pixel_weight=pixel_weight)

    def loss_fn(theta: Params, active, rgb, depth, camera: Camera, pixel_weight, background,
                *extra):
        loss = photometric(theta, active, rgb, depth, camera, pixel_weight, background)
        return loss if penalty is None else loss + penalty(theta, *extra)

    def seen_grads(theta: Params, active, rgb, depth, camera, pixel_weight, background, *extra):
        """The loss and its gradient on the seen rows, with those rows ``[K]``."""
        loss, grads = jax.value_and_grad(photometric)(theta, active, rgb, depth, camera,
                                                      pixel_weight, background)
        rows = seen_rows(grads)
        if penalty is not None:
            cost, more = jax.value_and_grad(penalty)(theta, *extra)
            loss, grads = loss + cost, jax.tree.map(jnp.add, grads, more)
        return loss, _rows_where(rows, grads, jax.tree.map(jnp.zeros_like, grads)), rows

    @jax.jit
    def step(params: Params, opt_state, rgb, depth, camera: Camera, pixel_weight, background,
             *extra):
        if on_trace is not None:
            on_trace()
        theta = trainable(params)
        args = (theta, params.active, rgb, depth, camera, pixel_weight, background, *extra)
        if seen_only:
            loss, grads, rows = seen_grads(*args)
        else:
            loss, grads = jax.value_and_grad(loss_fn)(*args)
        grads = grads._replace(**{f: jnp.zeros_like(getattr(grads, f)) for f in frozen})
        updates, new_state = optimizer.update(grads, opt_state, theta)
        if seen_only:
            updates = _rows_where(rows, updates, jax.tree.map(jnp.zeros_like, updates))
            new_state = keep_rows(new_state, opt_state, rows)
        theta = optax.apply_updates(theta, updates)
        return theta._replace(active=params.active), new_state, loss

    return step


@functools.lru_cache(maxsize=STEP_CACHE_SIZE)
def _optimizer_and_step(config, extent, make_step_fn):
    """Optimiser and jitted step, shared by trainers with equal settings so that a new
    trainer (a new sweep cell, a new learner) reuses the compiled step."""
    optimizer = make_optimizer(config, extent)
    return optimizer, make_step_fn(config, optimizer)


def key_entropy(key: jax.Array) -> tuple[int, ...]:
    """A JAX key's bits as host integers (seed material for :func:`pick`)."""
    return tuple(int(x) for x in np.asarray(jax.random.key_data(key)).ravel())


def pick(entropy: tuple[int, ...], step: int, n: int) -> int:
    """The frame of step ``step``: uniform in ``[0, n)``, a function of the key's bits and
    the step alone, so a run's draws do not depend on how its steps were split into
    ``train`` calls (a run of N steps is the first N steps of a longer one). NumPy on the
    host: no device round trip between the steps."""
    return int(np.random.default_rng((*entropy, step)).integers(n))


class TrainState(NamedTuple):
    """What the training loop carries."""

    params: Params
    opt_state: optax.OptState
    step: int  # steps taken (host int: it schedules densification)
    key: jax.Array


class Trainer:
    """The baseline's training loop: draws frames, steps, densifies on schedule.

    Everything a step does is a function of its step count and the key (the learning
    rates, the frame drawn, :func:`pick`; the key changes only at a relocation, which is
    due at fixed steps), so ``train(state, frames, 100)`` then ``train(..., 200)`` equals
    ``train(state, frames, 300)``: a run of N steps is the first N of a longer run.

    ``state = trainer.init(params, key=key)``; ``state, losses = trainer.train(state,
    frames, n_steps)`` with each step's frame drawn uniformly from ``frames``.
    ``make_step_fn(config, optimizer)`` builds the step (default :func:`make_step`;
    the 2-D image trainer passes its own).
    """

    def __init__(self, config: TrainConfig, *, extent: float, make_step_fn=make_step):
        self.config = config
        self.optimizer, self.step_fn = _optimizer_and_step(config, float(extent), make_step_fn)

    def init(self, params: Params, *, key: jax.Array) -> TrainState:
        return TrainState(params, self.optimizer.init(trainable(params)), 0, key)

    def densify(self, state: TrainState) -> TrainState:
        """One relocation round (:func:`vbgs.baseline.densify.relocate`), moments reset."""
        dcfg = self.config.densify
        key, sub = jax.random.split(state.key)
        score = gradient_score(state.opt_state) if dcfg.sample_by == "gradient" else None
        params, changed = relocate(state.params, sub, score, config=dcfg)
        return state._replace(params=params, opt_state=reset_moments(state.opt_state, changed),
                              key=key)

    def train(self, state: TrainState, frames: list, n_steps: int, *shared
              ) -> tuple[TrainState, np.ndarray]:
        """``n_steps`` steps, each on a frame drawn uniformly from ``frames`` (Frames, or
        tuples of arrays such as FrameArrays, passed to the step as ``*args``, followed
        by the ``shared`` arguments, e.g. the scene step's background); returns the new
        state and the losses ``[n_steps]``."""
        if not frames:
            raise ValueError("no frames to train on")
        arrays = [frame_arrays(f) if hasattr(f, "camera") else f for f in frames]
        entropy = key_entropy(state.key)
        losses = []
        params, opt_state = state.params, state.opt_state
        for _ in range(n_steps):
            i = pick(entropy, state.step, len(arrays))
            params, opt_state, loss = self.step_fn(params, opt_state, *arrays[i], *shared)
            losses.append(loss)
            state = state._replace(params=params, opt_state=opt_state, step=state.step + 1)
            if self.config.densify is not None and self.config.densify.due(state.step):
                state = self.densify(state)
                params, opt_state = state.params, state.opt_state
                entropy = key_entropy(state.key)
        return state, np.asarray(jnp.stack(losses)) if losses else np.zeros(0, np.float32)
