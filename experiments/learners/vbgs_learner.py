"""VBGS as a continual scene learner: each arriving frame is one :func:`vbgs.inference.model.update`.

With ``task.init == "stream"`` the learner starts empty and, before each frame is
learned, adds components where the frame shows ground the model has no component for
(:func:`vbgs.inference.grow.grow`); the first frame fixes the cell side by getting
FIRST_FRAME_SHARE of the capacity. ``data`` and ``random`` start from the prior of
:func:`experiments.learners.start.scene_prior` (an oracle start).

With ``task.colour_rule == "fit"`` each frame also adds its terms of the colour
least squares (:mod:`vbgs.render.colour_fit`), its blending weights W_f rendered from the
posterior just after the frame's update: the model that learned the frame is the
best one to say which components paint its pixels, and under stream init a component
grown late has rows from the frames that arrived after it only, as it should.
:meth:`VbgsLearner.splats` solves for the colours.
"""

from __future__ import annotations

import jax

from experiments.learners.start import FIRST_FRAME_SHARE, REFINE_SHARE, init_key, scene_prior
from experiments.protocol import SceneResult, frame_points
from vbgs.render import colour_fit, opacity
from vbgs.inference import grow, model, skip
from vbgs.inference.bound import StreamBound, batch_bound
from vbgs.data.scene import Frame, Scene
from vbgs.render.splats import Splats, from_posterior, mixture_geometry
from vbgs.inference.stepper import Stepper


class VbgsLearner:
    """A :class:`experiments.protocol.Learner`: conjugate updates, no replay."""

    PROTOCOLS = ("continual",)  # VBGS always streams
    replay_bytes = 0

    def __init__(self, task, scene: Scene):
        self.task = task
        self.key = init_key(task)
        self.rule: grow.Growth | None = None
        self.state = None if task.init == "stream" else model.start(scene_prior(task, scene))
        self.step: Stepper | None = None  # compiled update, told when the reference grows
        self.step_prior: model.Mixture | None = None  # the reference the stepper holds
        self.prior_geometry = None  # means and covariances of that reference (evidence)
        self.evidence = opacity.no_evidence(task.components)
        self.colour = colour_fit.no_frames(task.components)  # colour normal equations
        self.bound = StreamBound()
        self._last: tuple | None = None  # (q before the frame, xyz, rgb) for diagnose
        self.points_seen = self.points_skipped = self.frames_skipped = 0

    @property
    def blur(self) -> float:
        """The pixel filter (px²) its splats are rendered with: the task's ``splat_blur``
        (:data:`vbgs.render.splats.VBGS_BLUR`)."""
        return self.task.splat_blur

    @property
    def prior(self) -> model.Mixture:
        """The current reference model (it grows under ``init="stream"``)."""
        if self.state is None:
            raise ValueError("the stream has not started: no frame has arrived yet")
        return self.state.prior

    def _sync_stepper(self, grown) -> None:
        """Build the stepper on the first frame; after growth (the slots ``grown``) hand it
        the grown reference (:meth:`vbgs.inference.stepper.Stepper.grow`: no recompilation)."""
        t = self.task
        if self.step is None:
            grows = t.init == "stream"
            self.step = Stepper(self.state.prior, assign=t.assign, config=t.prior,
                                estep=t.estep, n_candidates=t.candidates, grows=grows,
                                reach=grow.reach_of(self.rule)
                                if grows and t.estep == "sparse" else None)
        elif self.step_prior is not self.state.prior:
            self.step.grow(self.state.prior, grown)
        else:
            return
        self.step_prior = self.state.prior
        self.prior_geometry = mixture_geometry(self.state.prior)

    @staticmethod
    def check(task) -> None:
        """Nothing to check beyond the task's own validation."""

    def _grow(self, xyz, rgb):
        """Fill empty slots on the frame's poorly explained points; the slots filled."""
        t = self.task
        if self.state is None:
            self.rule = grow.calibrate(xyz, t.components, FIRST_FRAME_SHARE * t.components,
                                       refine=REFINE_SHARE)
            self.state = grow.start_empty(xyz, t.components, self.rule.cell, t.prior)
        self.key, sub = jax.random.split(self.key)
        self.state, info = grow.grow(self.state, xyz, rgb, self.rule, key=sub, config=t.prior)
        return info.slots

    def learn(self, frame: Frame, background=None) -> None:
        """Grow (stream init), then one conjugate update with the frame's points. The
        background is not surface: pixels without depth are not points, so it plays no
        part here."""
        xyz, rgb = frame_points(frame)
        t = self.task
        grown = self._grow(xyz, rgb) if t.init == "stream" else None
        self._sync_stepper(grown)  # the compiled stepper holds the reference's terms
        if t.opacity_rule == "evidence":  # the whole depth map, skipped points or not, read
            # against the model that assigns the points
            geometry = (self.prior_geometry if t.assign == "prior"
                        else mixture_geometry(self.state.posterior))
            self.evidence = opacity.observe(self.evidence, *geometry, frame.camera, frame.depth)
        self.points_seen += len(xyz)
        if t.skip_margin is not None:
            keep = ~skip.well_explained(self.state.posterior, self.state.stats.count, xyz, rgb,
                                        margin=t.skip_margin, colour_noise=t.prior.colour_noise)
            self.points_skipped += int((~keep).sum())
            if not keep.any():
                self.frames_skipped += 1
                self._last = None
                self._observe_colour(frame, background)
                return
            xyz, rgb = xyz[keep], rgb[keep]
        before = self.state.posterior
        self.state, _ = self.step(self.state, xyz, rgb)
        learned = self.step.learned  # points beyond reach were left out: not in the bound
        if learned is None:
            self._last = (before, xyz, rgb)
        else:  # nothing learned, nothing to bound (q_t = q_{t-1})
            self._last = (before, xyz[learned], rgb[learned]) if learned.any() else None
        jax.block_until_ready(self.state.stats.count)
        self._observe_colour(frame, background)

    def _observe_colour(self, frame: Frame, background) -> None:
        """Add the frame's colour least-squares terms (``colour_rule == "fit"``), against
        the splats of the posterior that has just learned it (no background: black)."""
        if self.task.colour_rule != "fit":
            return
        self.colour = colour_fit.observe(self.colour, self.posterior_splats(), frame.camera,
                                         frame.rgb, 0.0 if background is None else background,
                                         blur=self.blur)
        jax.block_until_ready(self.colour.rhs)

    def splats(self, drop_unused: bool = False) -> Splats:
        colours = None
        if self.task.colour_rule == "fit":
            colours = colour_fit.solve(self.colour, self.state.posterior.colour.mean,
                                       ridge=self.task.colour_ridge)
        return self.posterior_splats(drop_unused, colours)

    def posterior_splats(self, drop_unused: bool = False, colours=None) -> Splats:
        """The posterior's splats (opacity by the task's rule), with ``colours`` [k, 3]
        in place of the posterior colour means when given."""
        evidence = self.task.opacity_rule == "evidence"
        return from_posterior(self.state.posterior, self.prior, opacity=self.task.opacity,
                              cov_scale=self.task.splat_scale, drop_unused=drop_unused,
                              opacities=opacity.expected_opacity(self.evidence) if evidence
                              else None, colours=colours)

    def diagnose(self, frame: Frame) -> None:
        """Add the last frame's streaming bound ``B_t`` (:mod:`vbgs.inference.bound`; untimed) over
        the points it learned (none when the whole frame was skipped)."""
        if self._last is None:
            return
        before, xyz, rgb = self._last
        t = self.task
        self.bound = self.bound.add(batch_bound(before, self.state.posterior, xyz, rgb,
                                                config=t.prior, estep=t.estep,
                                                n_candidates=t.candidates))

    def details(self, result: SceneResult) -> dict:
        """The streaming bound (:meth:`vbgs.inference.bound.StreamBound.summary`), the share of
        points beyond the stream start's reach (:func:`vbgs.inference.grow.reach_of`) and, when
        skipping is on, the share of points skipped and the frames skipped whole."""
        skipped = {}
        if self.step is not None and self.step.reach is not None:
            skipped["points_unreached"] = self.step.unreached / max(self.points_seen, 1)
        if self.task.skip_margin is not None:
            skipped.update(points_skipped=self.points_skipped / max(self.points_seen, 1),
                           frames_skipped=self.frames_skipped)
        return {**self.bound.summary(), **skipped}
