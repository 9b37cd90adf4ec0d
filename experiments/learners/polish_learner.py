"""VBGS, then a photometric polish from its splats (``--method vbgs-polish``).

VBGS (:class:`experiments.learners.vbgs_learner.VbgsLearner`, unchanged) learns every
frame by its conjugate update. The polish trains the gradient baseline's parameters
(:mod:`vbgs.baseline`: its loss with the depth term, its Adam step and learning rates,
its replay buffers) starting exactly from VBGS's splats
(:func:`vbgs.baseline.params.params_from_splats`: all K rows, so the row of a splat is
its component's):

* ``protocol="static"``: VBGS streams every training frame, then ``task.steps`` steps
  on frames drawn uniformly from all of them;
* ``protocol="continual"``: after VBGS learns each arriving frame, ``task.steps_per_frame``
  steps on that frame and the replay buffer (``task.replay``, the baseline's), then the
  frame joins the buffer.

**What was chosen, and why.** The conjugate posterior keeps its role: the polish is a
residual on top of it, carried as it learns.

1. *The posterior keeps learning.* Each frame goes to VBGS first, and the polished
   splats are carried onto its new splats (:func:`vbgs.baseline.anchor.carry`: what the
   polish added stays, what the posterior learned is added, a covariance's in its
   logarithm), so a component VBGS moves
   moves its polished splat too, and the frames the polish no longer replays are still
   in the posterior's sufficient statistics.
2. *The residual is held where the frames before left it, by the posterior's own
   uncertainty* (:func:`vbgs.baseline.anchor.anchor_penalty`, added to the baseline's
   loss): each splat pays its divergence from its polished splat as the steps of the
   frames before left it (carried onto the posterior's new splat, item 1; at the first
   frame, the posterior's splat) under the posterior's precision (mean under
   ``Var[μ] = E[Σ] / κ``, covariance under the inverse-Wishart's ``ν``, colour under
   ``σ_c² / κ_c``, opacity under the Beta counts of rays). This is a recursive Laplace
   approximation: what frames ``1..t-1``'s pictures say about the splats is taken as a
   Gaussian around the polish they left, and lacking those pictures' own curvature the
   posterior's precision, which grows with the points the same frames gave each splat,
   stands in for it. A splat seen from many points moves little in a new frame's steps;
   one barely seen, or never, is free to follow the pictures. Centred on the posterior's
   splats instead (as the polish first was), the anchor holds forgetting down only by
   pulling every splat a step touches back to what the points alone say, which undoes
   the pictures' gains: on validation views the FIFO polish lost 1.0 dB (room) and 0.8 dB
   (walk) of final PSNR where centred on the polish it gained (ANCHOR_WEIGHT's note).
   The weight (``task.polish_anchor``, loss units per nat of the posterior per point) is
   chosen by protocol unless given (:func:`anchor_weight`): continual,
   :data:`vbgs.baseline.anchor.ANCHOR_WEIGHT`; static, 0 (a free polish: every frame is
   in every step's draw, so there is nothing to forget, and the free polish scored best
   on validation views). The residual and the carry stay either way.
3. *The past weighs what it saw against the frames drawn* (:func:`draw_points`). Each
   step's loss is one frame's mean per pixel, drawn from the current frame and the
   buffer, ``D``; so the steps minimise ``mean_{f∈D} ℓ_f(θ) + w A(θ) / P`` (``A`` the
   anchor's nats, ``w`` the weight). Read ``ℓ`` as a negative log-likelihood per pixel
   in units of ``b`` (ANCHOR_WEIGHT's note): the posterior of the splats given ``D`` and
   the past, ``-log p(θ | D, past) = Σ_{f∈D} n_f ℓ_f / b + A(θ)``, divided by the draw's
   ``|D| n̄`` points (``n̄`` the posterior's points per frame), is that objective with
   ``P = |D| n̄``. Dividing by every point the posterior learned from (``P = t n̄``
   after ``t`` frames, as before) let the past weigh one frame's worth however long the
   stream, so each new frame overwrote what earlier views needed; with ``P = |D| n̄``
   it weighs ``t / |D|`` times the draw, as a recursive update counts each frame once:
   without replay the anchor grows along the stream, with a FIFO of 8 it is 9 times
   weaker (the replayed frames hold their own ground). Static: ``D`` is every training
   frame, ``P`` all the points, as before.
4. *A step moves only what the drawn frame sees* (continual;
   :func:`vbgs.baseline.train.make_step` ``seen_only``). A splat the frame's picture does
   not depend on has no evidence in the step: its value is what the frames that saw it
   fitted, and Adam's momentum from those frames (or a penalty) would move it with
   nothing in the step to say so. Such a splat and its Adam moments are left as they
   are. (Static: every frame is in the draw, the step is the plain one.)
5. *A mean steps in its splat's shape* (continual;
   :func:`vbgs.baseline.anchor.shape_mean_steps`): the optimiser's update of a mean is
   scaled along each of the splat's axes by that axis's scale over the widest one, the
   anchor's own metric (``Var[μ] = E[Σ] / κ``). Adam steps every world coordinate by
   about its rate whatever the gradient says, so a flat splat's mean moved as far along
   its normal, where the points fixed it, as across its surface. (Static: the plain
   step, whose figures this rule was not measured on.)

Why the polish without replay went below VBGS before rule 5: Adam pushed the splats'
means off their surface along their thin axes, and views other than the one stepped on
saw them there (:mod:`experiments.studies.polish_residual` scores each part of the
residual on validation views; the figures are in docs/validation.md, "The continual
polish's residual").

Where it stands (validation views, ANCHOR_WEIGHT's note, with item 5): at the chosen weight
the CL forgetting (how far each segment ends below its best along the stream, averaged over
the segments) is at most 0.3 dB on the room and the walk, with no replay and with a FIFO of
8, and each cell's final PSNR is at least the polish's before this rule but the walk's
FIFO (docs/validation.md, "ANCHOR_WEIGHT").

Not done: no densification (the rows are VBGS's components, and a moved row would lose
its anchor). The learning rates are the baseline's schedule of the step alone (the
position rate decays over :data:`experiments.learners.gradient_learner.SCENE_LR_DECAY_STEPS`
steps, never over the run's length): a polish of N steps is the first N steps of a longer
one, so ``front`` scores one run at several step counts. Splats are drawn with VBGS's pixel
filter throughout, so 0 steps render exactly VBGS's picture.

Wall time: ``seconds`` is VBGS's stream plus the polish under either protocol
(``seconds_vbgs`` and ``seconds_polish`` say the split; the static protocol alone would
time only the polish), ``seconds_compiling`` the compilation inside them.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np

from experiments.learners.gradient_learner import (
    DEFAULT_CONFIG,
    TRAIN_KEY,
    stream_extent,
    train_arrays,
)
from experiments.learners.start import init_key
from experiments.learners.vbgs_learner import VbgsLearner
from experiments.tasks.protocol import PROGRESS_BLOCK, SceneResult, frame_points, stream_frames
from vbgs.baseline import (
    Trainer,
    camera_extent,
    params_from_splats,
    parse_replay,
    reset_moments,
    to_splats,
)
from vbgs.baseline.anchor import (
    ANCHOR_WEIGHT,
    anchor_penalty,
    carry,
    make_anchor,
    shape_mean_steps,
)
from vbgs.baseline.train import make_step
from vbgs.compilation import compile_seconds
from vbgs.data.scene import Frame, Scene
from vbgs.data.streams import stream_order
from vbgs.render.raster import exact_capacity
from vbgs.render.splats import Splats, drawn


# The static protocol's anchor weight (see the module docstring and ANCHOR_WEIGHT's note).
STATIC_ANCHOR = 0.0


def anchor_weight(task) -> float:
    """``task.polish_anchor``, or by protocol when it is None: ANCHOR_WEIGHT when
    continual, STATIC_ANCHOR when static."""
    if task.polish_anchor is not None:
        return float(task.polish_anchor)
    return STATIC_ANCHOR if task.protocol == "static" else ANCHOR_WEIGHT


def anchored_step(config, optimizer):
    """The baseline's step with the anchor's penalty (one function: the compiled step
    is shared by learners with equal settings, see :class:`vbgs.baseline.Trainer`)."""
    return make_step(config, optimizer, penalty=anchor_penalty)


def anchored_seen_step(config, optimizer):
    """:func:`anchored_step` moving only the rows the drawn frame sees (a stream's), each
    mean's step shaped by its splat (:func:`vbgs.baseline.anchor.shape_mean_steps`)."""
    return make_step(config, shape_mean_steps(optimizer), penalty=anchor_penalty,
                     seen_only=True)


def draw_points(points: float, n_learned: int, n_draw: int) -> float:
    """``P = |D| n̄``: the points of the ``n_draw`` frames the steps draw from, at the
    posterior's mean points per frame (``points`` learned from ``n_learned`` frames);
    the anchor's nats are divided by it (module docstring, item 3)."""
    return points * n_draw / max(n_learned, 1)


class PolishLearner:
    """A :class:`experiments.tasks.protocol.Learner` that can also ``train`` on all frames."""

    PROTOCOLS = ("continual", "static")

    def __init__(self, task, scene: Scene):
        self.task = task
        self.vbgs = VbgsLearner(task, scene)
        self.blur = self.vbgs.blur
        # the baseline's per-step schedule (module docstring), no densification
        self.config = replace(DEFAULT_CONFIG, densify=None, blur=self.blur)
        self.replay = parse_replay(task.replay, seed=task.seed)
        self.extent = (camera_extent([f.camera.position for f in scene.train])
                       if task.protocol == "static" else None)
        self.trainer = self.state = self.anchor = self._base = None
        self._step_fn = anchored_seen_step if task.protocol == "continual" else anchored_step
        self.losses: list[np.ndarray] = []
        self.seconds = {"vbgs": 0.0, "polish": 0.0, "compiling": 0.0}

    @staticmethod
    def check(task) -> None:
        """Refuses VBGS's bad settings, a bad replay spec, and a replay buffer under the
        static protocol (which trains on every frame), before any work."""
        VbgsLearner.check(task)
        parse_replay(task.replay)
        if task.protocol == "static" and task.replay != "none":
            raise ValueError(f"--replay {task.replay} has no meaning under --protocol static "
                             f"(the polish trains on every training frame): drop --replay, "
                             f"or use the continual protocol")

    @property
    def replay_bytes(self) -> int:
        """Bytes of the frames (rgb + depth) the replay buffer holds."""
        return self.replay.nbytes

    @contextmanager
    def _timed(self, part: str):
        """Add the block's wall seconds to ``part`` and its compilation to ``compiling``."""
        start, compiled = time.perf_counter(), compile_seconds()
        yield
        self.seconds[part] += time.perf_counter() - start
        self.seconds["compiling"] += compile_seconds() - compiled

    def _learn_vbgs(self, frame: Frame, background) -> None:
        with self._timed("vbgs"):
            self.vbgs.learn(frame, background)

    def _rebase(self, frames: list) -> None:
        """Carry the polish onto VBGS's current splats, anchor it there (module docstring,
        items 2 and 3), and make sure the rasterizer's capacity drops nothing in
        ``frames`` (anything with a ``camera``: the frames the steps draw from)."""
        splats = self.vbgs.splats()
        base = params_from_splats(splats)
        mix, state, cfg = self.vbgs.state.mixture, self.vbgs.state, self.vbgs.config
        post = mix.posterior
        evidence = cfg.evidence
        capacity = max(exact_capacity(splats, f.camera, blur=self.blur) for f in frames)
        if self.trainer is None or capacity > self.trainer.config.raster_capacity:
            self.trainer = Trainer(replace(self.config, raster_capacity=capacity),
                                   extent=self.extent, make_step_fn=self._step_fn)
        if self.state is None:
            key = jax.random.fold_in(init_key(self.task), TRAIN_KEY)
            self.state = self.trainer.init(base, key=key)
        else:
            params, changed = carry(self.state.params, self._base, base)
            self.state = self.state._replace(
                params=params, opt_state=reset_moments(self.state.opt_state,
                                                       jnp.asarray(changed)))
        self._base = base
        self.anchor = make_anchor(
            self.state.params,  # the centre: the polish carried (module docstring, item 2)
            mean_strength=post.space.kappa * cfg.render.splat_scale**2,
            dof=post.space.dof, colour_precision=post.colour.kappa / cfg.prior.colour_noise**2,
            opacity_count=(evidence.prior_hits + evidence.prior_passes
                           + state.evidence.hits + state.evidence.passes),
            points=draw_points(float(jnp.sum(post.alpha - mix.prior.alpha)), state.n_frames,
                               len(frames)), weight=anchor_weight(self.task))

    def static_frames(self, scene: Scene) -> list:
        """VBGS streams every training frame (in the task's order, timed as VBGS's);
        the polish starts from its splats. Returns the frames as :meth:`train` takes
        them."""
        order = stream_order(len(scene.train), self.task.order, seed=self.task.seed)
        for _, frame, background in stream_frames(self.task, scene, order):
            self._learn_vbgs(frame, background)
        with self._timed("polish"):
            self._rebase(scene.train)
        return [train_arrays(self.task, f) for f in scene.train]

    def train(self, frames: list, n_steps: int, background) -> None:
        """``n_steps`` anchored steps on frames drawn uniformly from ``frames``."""
        with self._timed("polish"):
            self.state, losses = self.trainer.train(self.state, frames, n_steps,
                                                    jnp.asarray(background, jnp.float32),
                                                    self.anchor)
            jax.block_until_ready(self.state.params)
        self.losses.append(losses)

    def learn(self, frame: Frame, background) -> None:
        """VBGS learns the frame; the polish moves onto its splats, takes
        ``steps_per_frame`` steps on the frame and the replay buffer, buffers the frame."""
        self._learn_vbgs(frame, background)
        with self._timed("polish"):
            if self.extent is None:  # a stream knows its extent from its first frame
                self.extent = stream_extent(frame.camera.position, frame_points(frame)[0])
            self._rebase([frame, *self.replay.items])  # every view it will train on
        arrays = train_arrays(self.task, frame)
        self.train([arrays, *self.replay.items], self.task.steps_per_frame, background)
        self.replay = self.replay.add(arrays)

    def diagnose(self, frame: Frame) -> None:
        """VBGS's streaming bound (untimed), as the VBGS learner reports it."""
        self.vbgs.diagnose(frame)

    def splats(self, drop_unused: bool = False) -> Splats:
        """The polished splats (every row; with ``drop_unused`` only those drawn)."""
        if self.state is None:
            raise ValueError("the polish has seen no frame yet: there are no splats to show")
        splats = to_splats(self.state.params)
        return drawn(splats) if drop_unused else splats

    def details(self, result: SceneResult) -> dict:
        """VBGS's own details, the polish's steps, loss and anchor weight, and the wall
        time split (``seconds`` = VBGS + polish, see the module docstring)."""
        losses = np.concatenate(self.losses) if self.losses else np.zeros(0)
        last = losses[-PROGRESS_BLOCK:]
        return {**self.vbgs.details(result),
                "steps_total": int(losses.size),
                "final_loss": float(last.mean()) if last.size else float("nan"),
                "polish_anchor": anchor_weight(self.task),
                "seconds_vbgs": self.seconds["vbgs"], "seconds_polish": self.seconds["polish"],
                "seconds": self.seconds["vbgs"] + self.seconds["polish"],
                "seconds_compiling": self.seconds["compiling"]}
