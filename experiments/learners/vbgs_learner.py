"""VBGS as a continual scene learner: each arriving frame is one :func:`vbgs.model.update`.

With ``task.init == "stream"`` the learner starts empty and, before each frame is
learned, adds components where the frame shows ground the model has no component for
(:func:`vbgs.grow.grow`); the first frame fixes the cell side by getting
FIRST_FRAME_SHARE of the capacity. ``data`` and ``random`` start from the prior of
:func:`experiments.learners.start.scene_prior` (an oracle start).
"""

from __future__ import annotations

import jax

from experiments.learners.start import FIRST_FRAME_SHARE, REFINE_SHARE, init_key, scene_prior
from experiments.protocol import SceneResult, frame_points
from vbgs import grow, model, skip
from vbgs.bound import StreamBound, batch_bound
from vbgs.data.scene import Frame, Scene
from vbgs.splats import Splats, from_posterior


class VbgsLearner:
    """A :class:`experiments.protocol.Learner`: conjugate updates, no replay."""

    PROTOCOLS = ("continual",)  # VBGS always streams
    replay_bytes = 0

    def __init__(self, task, scene: Scene):
        self.task = task
        self.key = init_key(task)
        self.rule: grow.Growth | None = None
        self.state = None if task.init == "stream" else model.start(scene_prior(task, scene))
        self.bound = StreamBound()
        self._last: tuple | None = None  # (q before the frame, xyz, rgb) for diagnose
        self.points_seen = self.points_skipped = self.frames_skipped = 0

    @property
    def prior(self) -> model.Mixture:
        """The current reference model (it grows under ``init="stream"``)."""
        if self.state is None:
            raise ValueError("the stream has not started: no frame has arrived yet")
        return self.state.prior

    @staticmethod
    def check(task) -> None:
        """Nothing to check beyond the task's own validation."""

    def _grow(self, xyz, rgb) -> None:
        t = self.task
        if self.state is None:
            self.rule = grow.calibrate(xyz, t.components, FIRST_FRAME_SHARE * t.components,
                                       refine=REFINE_SHARE)
            self.state = grow.start_empty(xyz, t.components, self.rule.cell, t.prior)
        self.key, sub = jax.random.split(self.key)
        self.state, _ = grow.grow(self.state, xyz, rgb, self.rule, key=sub, config=t.prior)

    def learn(self, frame: Frame) -> None:
        xyz, rgb = frame_points(frame)
        t = self.task
        if t.init == "stream":
            self._grow(xyz, rgb)
        self.points_seen += len(xyz)
        if t.skip_margin is not None:
            keep = ~skip.well_explained(self.state.posterior, self.state.stats.count, xyz, rgb,
                                        margin=t.skip_margin, colour_noise=t.prior.colour_noise)
            self.points_skipped += int((~keep).sum())
            if not keep.any():
                self.frames_skipped += 1
                self._last = None
                return
            xyz, rgb = xyz[keep], rgb[keep]
        self._last = (self.state.posterior, xyz, rgb)
        self.state, _ = model.update(self.state, xyz, rgb, assign=t.assign, config=t.prior,
                                     estep=t.estep, n_candidates=t.candidates)
        jax.block_until_ready(self.state.stats.count)

    def splats(self, drop_unused: bool = False) -> Splats:
        return from_posterior(self.state.posterior, self.prior, opacity=self.task.opacity,
                              cov_scale=self.task.splat_scale, drop_unused=drop_unused)

    def diagnose(self, frame: Frame) -> None:
        """Add the last frame's streaming bound ``B_t`` (:mod:`vbgs.bound`; untimed) over
        the points it learned (none when the whole frame was skipped)."""
        if self._last is None:
            return
        before, xyz, rgb = self._last
        t = self.task
        self.bound = self.bound.add(batch_bound(before, self.state.posterior, xyz, rgb,
                                                config=t.prior, estep=t.estep,
                                                n_candidates=t.candidates))

    def details(self, result: SceneResult) -> dict:
        """The streaming bound (:meth:`vbgs.bound.StreamBound.summary`) and, when skipping
        is on, the share of points skipped and the frames skipped whole."""
        skipped = {}
        if self.task.skip_margin is not None:
            skipped = {"points_skipped": self.points_skipped / max(self.points_seen, 1),
                       "frames_skipped": self.frames_skipped}
        return {**self.bound.summary(), **skipped}
