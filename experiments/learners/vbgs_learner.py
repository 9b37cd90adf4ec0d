"""VBGS as a continual scene learner: each arriving frame is one :func:`vbgs.model.update`."""

from __future__ import annotations

import jax

from experiments.learners.start import scene_prior
from experiments.protocol import SceneResult, frame_points
from vbgs import model, opacity
from vbgs.data.scene import Frame, Scene
from vbgs.splats import Splats, from_posterior, mixture_geometry
from vbgs.stepper import Stepper


class VbgsLearner:
    """A :class:`experiments.protocol.Learner`: conjugate updates, no replay."""

    PROTOCOLS = ("continual",)  # VBGS always streams
    replay_bytes = 0

    def __init__(self, task, scene: Scene):
        self.task = task
        self.prior = scene_prior(task, scene)
        self.state = model.start(self.prior)
        self.step = Stepper(self.prior, assign=task.assign, config=task.prior, estep=task.estep,
                            n_candidates=task.candidates)  # compiled once per stream
        self.evidence = opacity.no_evidence(task.components)
        self.prior_geometry = mixture_geometry(self.prior)  # the assigning model, prior mode

    @staticmethod
    def check(task) -> None:
        """Nothing to check beyond the task's own validation."""

    def learn(self, frame: Frame, background=None) -> None:
        """One conjugate update with the frame's points (the background is not surface:
        pixels without depth are not points, so it plays no part here)."""
        xyz, rgb = frame_points(frame)
        t = self.task
        if t.opacity_rule == "evidence":  # read against the model that assigns the points
            geometry = (self.prior_geometry if t.assign == "prior"
                        else mixture_geometry(self.state.posterior))
            self.evidence = opacity.observe(self.evidence, *geometry, frame.camera, frame.depth)
        self.state, _ = self.step(self.state, xyz, rgb)
        jax.block_until_ready(self.state.stats.count)

    def splats(self, drop_unused: bool = False) -> Splats:
        evidence = self.task.opacity_rule == "evidence"
        return from_posterior(self.state.posterior, self.prior, opacity=self.task.opacity,
                              cov_scale=self.task.splat_scale, drop_unused=drop_unused,
                              opacities=opacity.expected_opacity(self.evidence) if evidence
                              else None)

    def details(self, result: SceneResult) -> dict:
        """Learner-specific numbers for the run's record (none yet)."""
        return {}
