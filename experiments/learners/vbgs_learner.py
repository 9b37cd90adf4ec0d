"""VBGS as a continual scene learner: an adapter over :mod:`vbgs.mapping`.

The task's settings become one :class:`vbgs.mapping.Config` (:func:`task_config`);
``init="stream"`` starts the map empty (it grows as frames arrive), ``data`` and
``random`` start it from the prior of :func:`experiments.learners.start.scene_prior`
(an oracle start: it reads every training frame).
"""

from __future__ import annotations

from contextlib import nullcontext

import jax
import numpy as np

from experiments.learners.start import init_key, scene_prior
from experiments.tasks.protocol import COMPILE_FRAMES, SceneResult, task_sensor
from experiments.tasks.settings import AUTO_SCALE, AUTO_SCALE_FRAMES
from vbgs import mapping
from vbgs.mapping import stages
from vbgs.data.scene import Frame, Scene
from vbgs.inference.bound import StreamBound
from vbgs.inference.grow import is_active
from vbgs.mapping.measurement import depth_sigmas, point_rays
from vbgs.baseline.replay import Replay
from vbgs.render.scale_fit import SCALES, choose_scale, rescaled
from vbgs.render.splats import VBGS_COV_SCALE, Splats
from vbgs.tracking import photometric, register
from vbgs.tracking.photometric import PhotoConfig
from vbgs.tracking.register import Registration, TrackConfig


def task_config(task) -> mapping.Config:
    """The mapping config of a scene task (its VBGS settings, one place each); with
    ``splat_scale = "auto"`` the splats are made at the default scale and redrawn at the
    chosen one (:class:`VbgsLearner`)."""
    scale = VBGS_COV_SCALE if task.splat_scale == AUTO_SCALE else task.splat_scale
    render = mapping.RenderConfig(
        splat_scale=scale, splat_blur=task.splat_blur,
        opacity_rule=task.opacity_rule, opacity=task.opacity,
        colour_rule=task.colour_rule, colour_ridge=task.colour_ridge)
    return mapping.Config(components=task.components, assign=task.assign, estep=task.estep,
                          candidates=task.candidates, search=task.search,
                          prior=task.prior, growth=task.growth,
                          evidence=task.evidence, render=render,
                          sensor=task_sensor(task), budget=task.budget)


class VbgsLearner:
    """A :class:`experiments.tasks.protocol.Learner`: conjugate updates, no replay. With
    ``splat_scale = "auto"`` it keeps a uniform sample of the arrived frames
    (``reservoir:AUTO_SCALE_FRAMES``, counted in ``replay_bytes``) to choose the splat
    scale on (:mod:`vbgs.render.scale_fit`) each time its splats are drawn.

    Its frames are pipelined (``pipelined``, on unless stages are timed): what a frame's
    see-throughs forget is decided while the next frame grows (:func:`vbgs.mapping.update`'s
    ``defer``), and reading :attr:`state` settles it first (:meth:`settle`), so
    whatever reads the map reads what an unpipelined stream would have learned."""

    PROTOCOLS = ("continual",)  # VBGS always streams

    def __init__(self, task, scene: Scene):
        self.task = task
        prior = None if task.init == "stream" else scene_prior(task, scene)
        self.pipelined = not task.stage_times  # timed stages wait for their own work
        self.state = mapping.init(self.config, key=init_key(task), prior=prior)
        self.skip = 0  # frames a resumed map learned already
        self.resumed = None  # the frames the map was saved after (--resume-map)
        if task.resume_map:
            self.state = mapping.load(task.resume_map, self.config)
            self.skip = self.resumed = self.state.n_frames
        self.learned = 0  # frames this run has learned
        self.stage_seconds: dict[str, float] = {}  # summed over the steady frames timed
        self.timed_frames = 0
        self.info: mapping.MapInfo | None = None  # the last frame's, for diagnose
        self.bound = StreamBound()
        self.arrived = Replay("reservoir", AUTO_SCALE_FRAMES, seed=task.seed)
        self.background = None  # the last frame's, to draw the arrived frames over
        self.scale: tuple[int, float, list[float]] | None = None  # (frames, scale, scores)

    @property
    def state(self) -> mapping.MapState:
        """The map, settled (:meth:`settle`)."""
        self.settle()
        return self._state

    @state.setter
    def state(self, state: mapping.MapState) -> None:
        self._state = state

    def settle(self) -> None:
        """Decide what the last frame's see-throughs forget, if a pipelined frame left
        it to the next (:func:`vbgs.mapping.settled`)."""
        if self._state.unjudged:
            self._state = mapping.settled(self._state, self.config)

    @property
    def auto_scale(self) -> bool:
        """The splat scale is chosen on the arrived frames (``splat_scale = "auto"``)."""
        return self.task.splat_scale == AUTO_SCALE

    @property
    def replay_bytes(self) -> int:
        """Bytes of the frames kept to choose the splat scale on (0 without auto)."""
        return self.arrived.nbytes

    @property
    def config(self) -> mapping.Config:
        """The task's mapping config (read anew: a tuning view swaps the task)."""
        return task_config(self.task)

    @property
    def blur(self) -> float:
        """The pixel filter (px²) its splats are rendered with."""
        return self.config.render.splat_blur

    @staticmethod
    def check(task) -> None:
        """Refuses settings the mapping config refuses, before any work."""
        task_config(task)

    def learn(self, frame: Frame, background=None) -> bool:
        """Learn the frame (False: skipped, learned before the map was saved)."""
        if self.skip:  # learned before the map was saved: the stream resumes after it
            self.skip -= 1
            return False
        steady = self.learned >= COMPILE_FRAMES  # as seconds_per_frame counts this run's
        self.learned += 1
        with stages.timing() if self.task.stage_times else nullcontext({}) as seconds:
            self._state, self.info = mapping.update(self._state, frame, self.config,
                                                    background, defer=self.pipelined)
        for name, value in seconds.items() if steady else ():
            self.stage_seconds[name] = self.stage_seconds.get(name, 0.0) + value
        self.timed_frames += bool(seconds) and steady
        jax.block_until_ready((self._state.mixture.stats.count, self._state.colour.rhs))
        if self.task.save_map:  # atomically: a run killed now loses only this frame
            mapping.save(self.task.save_map, self.state)
        if self.auto_scale:
            self.arrived = self.arrived.add(frame)
            self.background = background
        return True

    def splats(self, drop_unused: bool = False) -> Splats:
        splats = mapping.splats(self.state, self.config, drop_unused)
        if not self.auto_scale or not self.arrived.items:
            return splats
        base = self.config.render.splat_scale
        if self.scale is None or self.scale[0] != self.state.n_frames:  # once a frame
            every = mapping.splats(self.state, self.config) if drop_unused else splats
            chosen = choose_scale(every, list(self.arrived.items),
                                  0.0 if self.background is None else self.background,
                                  self.blur, base)
            self.scale = (self.state.n_frames, *chosen)
        return rescaled(splats, base, self.scale[1])

    def diagnose(self, frame: Frame) -> None:
        """Add the last frame's streaming bound ``B_t`` (untimed) over the points it
        learned, when the task asks for it (``streaming_bound``)."""
        if self.task.streaming_bound and self.info is not None and self.info.n_learned:
            self.bound = self.bound.add(mapping.bound(self.info, self.config))

    def details(self, result: SceneResult) -> dict:
        """The streaming bound (:meth:`vbgs.inference.bound.StreamBound.summary`; when
        the task asks for it), the median points a component holds and, for a map that
        grows, the share of points no component learned."""
        extra = {"points_per_component": self.state.points_per_component}
        if self.resumed is not None:  # the stream went on from a map saved after this frame
            extra["frames_resumed"] = self.resumed
        if self.stage_seconds:  # each stage's mean seconds a steady frame
            frames = max(self.timed_frames, 1)
            extra["stage_seconds"] = {k: v / frames for k, v in self.stage_seconds.items()}
        if self.scale is not None:  # splat_scale "auto": what the arrived frames chose
            extra.update(splat_scale_chosen=self.scale[1],
                         splat_scale_scores=dict(zip(map(str, SCALES), self.scale[2],
                                                     strict=True)))
        if self.state.growing and self.config.estep == "sparse":
            extra["points_unlearned"] = self.state.points_unlearned
        if self.state.stepper is not None:  # the candidate search the frames took
            extra["search_used"] = self.state.stepper.search
        if self.state.growing:  # seen through frames in a row: gone (vbgs.mapping.change)
            extra["components_forgotten"] = self.state.n_forgotten
            # rounds of merges that made room for new ground, and the components merged
            extra.update(merge_rounds=self.state.n_merge_rounds,
                         components_merged=self.state.n_merged)
        if self.config.budget.saturation:  # valid points skipped as already explained
            seen = self.state.n_points + self.state.n_skipped
            extra["points_skipped"] = self.state.n_skipped / max(seen, 1)
        if self.config.auto and self.state.mixture is not None:  # the K the data chose
            prior = self.state.mixture.prior
            extra.update(components_chosen=int(is_active(prior).sum()),
                         components_capacity=int(prior.n_components),
                         components_capped=bool(self.state.capped))
        return {**(self.bound.summary() if self.task.streaming_bound else {}), **extra}

    def _photo_inputs(self, frame: Frame, background, photo: PhotoConfig) -> dict:
        """The frame's depth, the sensor's sigma_z at each reading (None with exact
        depth, or when ``photo`` has no depth term), the background and the pixel filter
        of the renders."""
        sensor = self.config.sensor
        depth = np.asarray(frame.depth, np.float64)
        sigma = (depth_sigmas(depth, frame.camera, sensor.model, sensor.level)
                 if sensor.noisy and photo.depth else None)
        return dict(depth=depth, depth_sigma=sigma, blur=self.blur,
                    background=np.zeros(3) if background is None else background)

    def photo_costs(self, frame: Frame, poses, photo: PhotoConfig, background=None):
        """The frame's photometric cost at each of ``poses [m, 4, 4]`` against the map
        (:func:`vbgs.tracking.photometric.search`)."""
        return photometric.search(self.splats(), frame.camera, frame.rgb, poses, photo,
                                  **self._photo_inputs(frame, background, photo))

    def locate(self, frame: Frame, guess, config: TrackConfig, seed: int = 0, *,
               photo: PhotoConfig | None = None, background=None) -> Registration:
        """The frame's pose registered against the map learned so far, from ``guess``
        (:func:`vbgs.tracking.register.register`; the frame's own pose is not read), with
        its colours and the task's sensor noise along the rays when the depth is
        measured; with ``photo``, then refined against the map's splats rendered over
        ``background`` (:func:`vbgs.tracking.photometric.refine`, the measured depth
        weighted by the sensor's ``1 / sigma_z^2``), whose uncertainty it then reports."""
        state, sensor = self.state, self.config.sensor
        if state.mixture is None:
            raise ValueError("the map has seen no frame yet: give the first pose")
        ray = None
        if sensor.noisy:  # the noise in the camera frame: the pose is what is sought
            camera = frame.camera._replace(pose=np.eye(4))
            ray = point_rays(camera, frame.depth, sensor.model, sensor.level)
        found = register.target(state.mixture.posterior, state.mixture.prior)
        found = register.register(found, frame.camera, frame.depth, guess, config,
                                  rgb=frame.rgb, ray=ray, seed=seed)
        if photo is None:
            return found
        refined = photometric.refine(self.splats(), frame.camera, frame.rgb, found.pose, photo,
                                     **self._photo_inputs(frame, background, photo))
        return found._replace(pose=refined.pose, sigma_t=refined.sigma_t,
                              sigma_r_deg=refined.sigma_r_deg)
