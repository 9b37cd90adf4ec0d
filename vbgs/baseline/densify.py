"""Densification within a fixed capacity: move dead splats onto live ones (3DGS-MCMC spirit).

Every ``DensifyConfig.every`` steps, rows become *targets*:

* dead rows: active but ``sigmoid(opacity_logit) < dead_opacity`` (they contribute
  nothing, and below 1/255 the rasterizer culls them, so they would never recover);
* growth rows: up to ``floor(grow_rate · n_live)`` inactive rows (lowest index first),
  so the live count grows towards the capacity without any shape change.

Each target j draws a live source s_j with probability proportional to the source's
opacity (``sample_by="opacity"``) or to an accumulated positional-gradient score
(``"gradient"``; the trainer passes ``sqrt(Σ_d ν_means)`` from Adam's second moment,
a running mean of squared world-space gradients, in place of 3DGS's view-space one).
A source drawn ``n_s`` times is split into ``N_s = n_s + 1`` splats:

    o' = 1 - (1 - o_s)^(1 / N_s)     (N stacked copies composite to the source's α)
    s' = s_s / SPLIT_SCALE_DIVISOR   (3DGS's split shrink, for source and copies)
    μ_j = μ_s + R_s diag(s_s) ε_j,  ε_j ~ N(0, I)   (a sample of the source's Gaussian)

Copies take the source's rotation and colour; the source keeps its mean. The rows that
changed are returned so the trainer can reset their optimiser moments.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp

from vbgs.baseline.params import Params, logit, rotation_matrices
from vbgs.inference.precision import mat_vec

DEAD_OPACITY = 0.005  # below this a splat is dead and its row is reused
SPLIT_SCALE_DIVISOR = 1.6  # 3DGS: children of a split get scale / 1.6
GROW_RATE = 0.05  # 3DGS-MCMC grows the live count by 5% per densification
SAMPLE_BY = ("opacity", "gradient")
OPACITY_CLIP = 1e-6  # keeps the split opacity's logit finite


@dataclass(frozen=True)
class DensifyConfig:
    """When and how to relocate (hyperparameters; see the module docstring)."""

    every: int = 100  # steps between relocations
    start: int = 100  # first step at which to relocate
    stop: int | None = None  # last step (None: never stop)
    dead_opacity: float = DEAD_OPACITY
    grow_rate: float = GROW_RATE
    sample_by: str = "opacity"

    def __post_init__(self):
        if self.sample_by not in SAMPLE_BY:
            raise ValueError(f"sample_by must be one of {SAMPLE_BY}, got {self.sample_by!r}")
        if self.every < 1 or self.start < 0:
            raise ValueError(f"every must be >= 1 and start >= 0, got {self.every}, {self.start}")
        if not 0.0 < self.dead_opacity < 1.0 or self.grow_rate < 0:
            raise ValueError("dead_opacity must be in (0, 1) and grow_rate >= 0")

    def due(self, step: int) -> bool:
        """Whether to relocate after ``step`` steps."""
        in_range = step >= self.start and (self.stop is None or step <= self.stop)
        return in_range and step > 0 and step % self.every == 0


def growth_rows(active, live, grow_rate: float) -> jax.Array:
    """The first ``floor(grow_rate · n_live)`` inactive rows, ``[K]`` bool."""
    n_grow = jnp.floor(grow_rate * jnp.sum(live)).astype(jnp.int32)
    inactive = ~active
    rank = jnp.cumsum(inactive) - 1  # position among the inactive rows
    return inactive & (rank < n_grow)


@partial(jax.jit, static_argnames=("config",))
def relocate(params: Params, key: jax.Array, score: jax.Array | None = None, *,
             config: DensifyConfig = DensifyConfig()) -> tuple[Params, jax.Array]:
    """One relocation round (module docstring). Returns ``(params, changed [K] bool)``.

    score: ``[K]`` non-negative sampling weights for ``sample_by="gradient"``.
    With no live splat nothing changes.
    """
    if config.sample_by == "gradient" and score is None:
        raise ValueError("sample_by='gradient' needs a score [K] (e.g. train.gradient_score)")
    k_src, k_noise = jax.random.split(key)
    opac = jax.nn.sigmoid(params.opacity_logits)  # [K]
    live = params.active & (opac >= config.dead_opacity)
    dead = params.active & ~live
    targets = dead | growth_rows(params.active, live, config.grow_rate)
    weight = opac if config.sample_by == "opacity" else score
    weight = jnp.where(live, jnp.maximum(weight, 0.0), 0.0)
    has_source = jnp.sum(weight) > 0
    targets = targets & has_source
    log_w = jnp.log(jnp.where(weight > 0, weight, 1.0)) + jnp.where(weight > 0, 0.0, -jnp.inf)
    log_w = jnp.where(has_source, log_w, 0.0)  # any valid distribution when nothing moves
    source = jax.random.categorical(k_src, log_w, shape=targets.shape)  # [K]
    source = jnp.where(targets, source, jnp.arange(targets.shape[0]))
    drawn = jnp.zeros(targets.shape, jnp.int32).at[source].add(targets.astype(jnp.int32))
    split = drawn > 0  # sources that get copies
    n_split = (drawn + 1).astype(opac.dtype)  # N_s for every row (1 where not a source)
    new_opac = 1.0 - (1.0 - opac) ** (1.0 / n_split)
    new_logit = logit(jnp.clip(new_opac, OPACITY_CLIP, 1.0 - OPACITY_CLIP))
    shrink = jnp.log(SPLIT_SCALE_DIVISOR)
    # Updated sources (row-wise), then every target copies its (updated) source.
    opacity_logits = jnp.where(split, new_logit, params.opacity_logits)
    log_scales = jnp.where(split[:, None], params.log_scales - shrink, params.log_scales)
    eps = jax.random.normal(k_noise, params.means.shape, params.means.dtype)  # [K, d]
    rot = rotation_matrices(params)[source]  # [K, d, d]
    offset = mat_vec(rot, jnp.exp(params.log_scales[source]) * eps)  # [K, d], elementwise
    tgt = targets[:, None]
    new = Params(
        means=jnp.where(tgt, params.means[source] + offset, params.means),
        log_scales=jnp.where(tgt, log_scales[source], log_scales),
        rotations=jnp.where(tgt, params.rotations[source], params.rotations),
        opacity_logits=jnp.where(targets, opacity_logits[source], opacity_logits),
        colour_logits=jnp.where(tgt, params.colour_logits[source], params.colour_logits),
        active=params.active | targets,
    )
    return new, targets | split
