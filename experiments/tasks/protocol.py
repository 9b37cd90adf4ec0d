"""One protocol for every scene learner: what a learner is, how it sees the stream,
how it is scored, and the typed record of a run.

* :class:`Learner`: ``learn(frame, background)``, ``splats(drop_unused=False)`` and
  ``replay_bytes``; VBGS and the gradient baseline both are one
  (:mod:`experiments.learners`).
* **Background**: with ``task.background == "auto"`` the background colour is
  estimated from the pixels without depth of the frames that have arrived
  (:mod:`vbgs.render.background`); learners train with it and every view is rendered and
  scored over it. ``"R,G,B"`` fixes it instead.
* :func:`stream_protocol` (continual): training frames arrive one at a time in the
  task's ``order``; nothing is replayed unless the learner has a replay buffer.
  **Early views** are the held-out test views nearest (camera centre) to the first
  EARLY_FRACTION of the streamed frames; their mean PSNR is measured right after
  those frames were learned (``early_psnr_when_seen``), at the end
  (``early_psnr_at_end``) and along the stream (``forgetting_curve``): the forgetting
  they suffer. With ``task.cl_segments = S`` it also measures the continual-learning
  matrix of the stream's S segments and its metrics (:mod:`experiments.tasks.continual`) at the
  same checkpoints: one render per view serves both.
* :func:`static_protocol`: a learner that can ``train(frames, n_steps)`` takes
  ``task.steps`` steps on all training frames, then is scored (no forgetting metrics).
  :func:`static_checkpoints` scores one such run at several step counts (the learners'
  schedules are per step, so each is what a run of that length gives), its seconds the
  training to that count, the scoring left out.
* Final metrics are over all test views: PSNR, SSIM, depth L1 (where the ground truth
  has depth; rendered depth is the alpha-normalised expected depth).
* **Validation views** (``scene.val``) are never scored here: they are for
  :func:`evaluate_validation`, which the tuning command (:mod:`experiments.studies.tune`) uses
  to choose render settings, so no setting is chosen on the test views.

This module imports only :mod:`vbgs` (and the init names): tasks and learners import
it, never the reverse.
"""

from __future__ import annotations

import resource
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from experiments.tasks.continual import FIELDS as CL_FIELDS
from experiments.tasks.continual import (
    ContinualScores,
    continual_scores,
    nearest_test_views,
    stream_segments,
)
from experiments.tasks.change_scores import FIELDS as CHANGE_FIELDS
from experiments.tasks.change_scores import change_scores, frames_before_change
from experiments.tasks.init_schemes import oracle_start
from experiments.progress import progress as progress_bar
from vbgs.compilation import compile_seconds
from vbgs.data.scene import Frame, Scene
from vbgs.data.streams import stream_order
from vbgs.mapping.config import SensorConfig
from vbgs.render import background as bg
from vbgs.render.camera import unproject
from vbgs.render.raster import BLUR_VARIANCE
from vbgs.render.splats import Splats, save_ply
from vbgs.render.views import Evaluation, evaluate

EARLY_FRACTION = 0.1  # the first 10% of the stream defines the "early" views
CURVE_POINTS = 10  # evaluations of the early views along the stream
COMPILE_FRAMES = 2  # the first frames' times include compilation: left out of the mean


@runtime_checkable
class Learner(Protocol):
    """A continual scene learner: sees each frame once, shows its splats at any time."""

    replay_bytes: int  # bytes of frames it holds for replay (0: none)
    blur: float  # px², the pixel filter its splats are rendered with (vbgs.render.raster.rasterize)

    def learn(self, frame: Frame, background: np.ndarray) -> bool | None:
        """Learn the frame; False when it was learned before (a map resumed from a
        file skips those, and they are not timed)."""

    def splats(self, drop_unused: bool = False) -> Splats: ...


def diagnose(learner, frame: Frame) -> None:
    """The learner's untimed per-frame diagnostics (``learner.diagnose(frame)``, an
    optional method of a Learner: the streaming bound of VBGS), run after ``learn``."""
    hook = getattr(learner, "diagnose", None)
    if hook is not None:
        hook(frame)



@dataclass(frozen=True)
class SceneResult:
    """The record of one scene run; :meth:`to_dict` is its flat JSON form (settings
    first, then the depth-source report, the metrics and the learner's details)."""

    settings: Mapping[str, Any]  # the task's fields (see task_settings)
    psnr: float
    ssim: float
    depth_l1: float | None  # None: no test view has depth (an RGB-only folder)
    seconds: float  # training time, all frames
    seconds_per_frame: float  # steady state (compilation left out) or seconds / frames
    peak_memory_mb: float
    components_used: int
    replay_bytes: int
    early_views: list[int] | None  # None under the static protocol
    early_psnr_when_seen: float | None
    early_psnr_at_end: float | None
    forgetting_curve: list[list[float]] | None  # [[frames seen, early-view PSNR], ...]
    dropped: int
    background_rgb: list[float]  # the RGB the views were rendered and scored over
    uncovered: float  # share of test pixels with a surface that the splats leave uncovered
    images: Mapping[str, list] = field(repr=False)  # "target" and "render" per test view
    depth: Mapping[str, Any] = field(default_factory=lambda: {"depth_source": "sensor"})
    details: Mapping[str, Any] = field(default_factory=dict)  # learner-specific numbers
    oracle_start: bool = False  # the start read frames that had not arrived (init data/random)
    # of ``seconds``, the compilation (or compile-cache loads) inside the timed training;
    # counted once vbgs.compilation.CompileTimer listens (the CLI's runs), else 0
    seconds_compiling: float = 0.0
    # the continual-learning matrix and metrics (JSON: cl_*); None under the static
    # protocol or without task.cl_segments
    continual: ContinualScores | None = None
    # a scene that changed while streamed: experiments.tasks.change_scores (None each else)
    changes: Mapping[str, Any] = field(default_factory=lambda: dict.fromkeys(CHANGE_FIELDS))

    METRICS = ("oracle_start", "psnr", "ssim", "depth_l1", "seconds", "seconds_compiling",
               "seconds_per_frame",
               "peak_memory_mb", "components_used", "replay_bytes", "early_views", "early_psnr_when_seen",
               "early_psnr_at_end", "forgetting_curve", "dropped", "background_rgb", "uncovered",
               "images")

    def to_dict(self, images: bool = True) -> dict:
        """Flat dict: settings, depth report, metrics (images under ``"images"``
        unless ``images=False``), details."""
        metrics = {name: getattr(self, name) for name in self.METRICS}
        if not images:
            metrics.pop("images")
        continual = (self.continual.to_dict() if self.continual is not None
                     else dict.fromkeys(CL_FIELDS))
        return {**self.settings, **self.depth, **metrics, **self.changes, **continual,
                **self.details}


def task_settings(task) -> dict:
    """The task's settings as a flat dict (hyperparameter objects left out)."""
    settings = asdict(task)
    for nested in ("prior", "growth", "evidence", "baseline"):
        settings.pop(nested, None)
    return settings


def scene_background(task, estimate: bg.BackgroundEstimate) -> np.ndarray:
    """The background ``[3]`` to train, render and score with: ``task.background`` if it
    is an RGB triple, else the estimate from the frames seen so far."""
    fixed = bg.parse_background(task.background)
    return fixed if fixed is not None else bg.colour(estimate)


def static_background(task, scene: Scene) -> np.ndarray:
    """The background ``[3]`` of the static protocol: the task's, or the estimate from all
    training frames (a static learner sees them all before it starts)."""
    estimate = bg.empty()
    for frame in scene.train:
        estimate = bg.observe(estimate, frame.rgb, frame.depth, holes=measured(task))
    return scene_background(task, estimate)


def task_sensor(task) -> SensorConfig:
    """How the task's training depth was measured (its ``sensor`` and ``sensor_level``),
    as every learner and the background estimate take it."""
    return SensorConfig(task.sensor, task.sensor_level)


def measured(task) -> bool:
    """The task's training depth comes from a sensor that leaves holes in surfaces: only
    :func:`vbgs.render.background.empty_pixels` are background."""
    return not task_sensor(task).exact


def frame_points(frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """Coloured world points ``xyz [n, 3]``, ``rgb [n, 3]`` of a frame's valid depth."""
    return unproject(frame.camera, frame.rgb, frame.depth)


def peak_memory_mb() -> float:
    """Peak resident memory of this process so far (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def early_views(scene: Scene, order: np.ndarray) -> list[int]:
    """Test views nearest (camera centre) to the first EARLY_FRACTION of the stream."""
    n_early = max(1, int(round(EARLY_FRACTION * len(order))))
    return nearest_test_views(scene, order[:n_early])




def evaluate_validation(splats: Splats, scene: Scene, background, blur: float = BLUR_VARIANCE
                        ) -> Evaluation:
    """:func:`evaluate` over the scene's validation views (never its test views); a scene
    without validation views is refused."""
    if not scene.val:
        raise ValueError(f"scene {scene.name!r} has no validation views; give the task "
                         f"n_val >= 1 (datasets: a transforms_val.json or val_every)")
    return evaluate(splats, scene.val, background, blur)


def stream_frames(task, scene: Scene, order: np.ndarray, *, progress: bool = False,
                  arrive=None):
    """Yield ``(step, frame, background)`` for the training frames in ``order`` (step
    counts from 1), the background estimated from the frames that have arrived (or
    fixed by the task, see :func:`scene_background`). ``arrive``: frames -> frames, a
    lazy stage the frames pass through as they arrive (estimated depth)."""
    estimate = bg.empty()
    frames = (scene.train[i] for i in order)
    if arrive is not None:
        frames = arrive(frames)
    bar = progress_bar(frames, total=len(order), desc="frames", unit="frame", enabled=progress)
    for step, frame in enumerate(bar, 1):
        estimate = bg.observe(estimate, frame.rgb, frame.depth, holes=measured(task))
        yield step, frame, scene_background(task, estimate)


def _final(scene: Scene, learner: Learner, background, ply: str | None
           ) -> tuple[Evaluation, int]:
    """Score every test view; save the used splats as PLY if asked; (scores, used)."""
    final = evaluate(learner.splats(), scene.test, background, learner.blur)
    kept = learner.splats(drop_unused=True)
    if ply:
        save_ply(ply, kept)
    return final, kept.count


def stream_protocol(task, scene: Scene, learner: Learner, *, progress: bool = False,
                    ply: str | None = None, arrive=None) -> SceneResult:
    """Feed the training frames to ``learner`` one at a time in the task's order,
    tracking the early views (and the segments' views with ``task.cl_segments``), then
    score every test view (see the module docstring)."""
    order = stream_order(len(scene.train), task.order, seed=task.seed)
    early_idx = early_views(scene, order)
    n_early = max(1, int(round(EARLY_FRACTION * len(order))))
    checkpoints = set(np.linspace(n_early, len(order), CURVE_POINTS).round().astype(int))
    segments = stream_segments(scene, order, task.cl_segments) if task.cl_segments else None
    # a changing world: the test views rendered once more just before its first changed
    # frame arrives (experiments.tasks.change_scores: the unchanged pixels' retention)
    change_step = frames_before_change(scene.changes, order)
    curve, frame_seconds, compiling, rows, cl_seconds = [], [], 0.0, [], 0.0
    before = None
    settle = getattr(learner, "settle", None)  # a pipelined learner's last frame's tail
    for step, frame, background in stream_frames(task, scene, order, progress=progress,
                                                 arrive=arrive):
        cl_views = segments.views_at(step) if segments else []
        looked_at = step in checkpoints or step == change_step or cl_views
        t0, c0 = time.perf_counter(), compile_seconds()
        if learner.learn(frame, background) is not False:  # False: learned before a resume
            if settle is not None and (looked_at or step == len(order)):
                settle()  # the frame's own work, before the map is read untimed
            frame_seconds.append(time.perf_counter() - t0)
            compiling += compile_seconds() - c0
        diagnose(learner, frame)
        if step == change_step:
            before = evaluate(learner.splats(), scene.test, background, learner.blur).renders
        if step in checkpoints or cl_views:
            t0 = time.perf_counter()
            shown = sorted(set(early_idx if step in checkpoints else []) | set(cl_views))
            scored = evaluate(learner.splats(), [scene.test[i] for i in shown], background,
                              learner.blur)
            view_psnr = dict(zip(shown, scored.view_psnr, strict=True))
            if step in checkpoints:
                curve.append([step, float(np.mean([view_psnr[i] for i in early_idx]))])
            if cl_views:
                rows.append(segments.row(view_psnr))
                cl_seconds += time.perf_counter() - t0
    final, used = _final(scene, learner, background, ply)
    if segments:  # the last row: the final evaluation of every test view
        rows.append(segments.row(dict(enumerate(final.view_psnr))))
    steady = frame_seconds[COMPILE_FRAMES:] or frame_seconds
    return SceneResult(
        settings=task_settings(task), psnr=final.psnr, ssim=final.ssim,
        depth_l1=final.depth_l1, seconds=float(np.sum(frame_seconds)),
        # no frame learned here (a map resumed after every frame): no time to report
        seconds_per_frame=float(np.mean(steady)) if steady else float("nan"), peak_memory_mb=peak_memory_mb(),
        components_used=used, replay_bytes=int(learner.replay_bytes), early_views=early_idx,
        early_psnr_when_seen=curve[0][1], early_psnr_at_end=curve[-1][1],
        forgetting_curve=curve, dropped=final.dropped, background_rgb=background.tolist(),
        uncovered=final.uncovered, images={"target": [f.rgb for f in scene.test], "render": final.renders},
        oracle_start=oracle_start(task.init), seconds_compiling=compiling,
        continual=continual_scores(segments, rows, cl_seconds) if segments else None,
        changes=change_scores(scene, final.renders, before))


PROGRESS_BLOCK = 50  # static protocol: steps between progress-bar updates


def static_protocol(task, scene: Scene, learner, frames: list, *, progress: bool = False,
                    ply: str | None = None) -> SceneResult:
    """``task.steps`` steps of ``learner.train(frames, n, background)`` on all training
    ``frames`` (in the learner's own form; the background estimated from all of them),
    then score the test views. No forgetting metrics; ``seconds_per_frame`` is the
    training time over the number of training frames."""
    (_, result), = static_checkpoints(task, scene, learner, frames, (task.steps,),
                                      progress=progress, ply=ply)
    return result


def static_checkpoints(task, scene: Scene, learner, frames: list, checkpoints, *,
                       progress: bool = False, ply: str | None = None):
    """One static run to the largest of ``checkpoints`` (step counts), yielding
    ``(steps, SceneResult)`` at each as :func:`static_protocol` scores a run of that
    many steps. Each result's ``seconds`` (and ``seconds_compiling``) is the training to
    that count, cumulative; the test views' scoring in between is not timed. A learner's
    steps must depend on the step count alone (per-step schedules and draws, as the
    baseline's :class:`vbgs.baseline.Trainer`) for a checkpoint to equal a run of its
    length. ``ply``: the splats of the last checkpoint."""
    counts = sorted({int(n) for n in checkpoints})
    if not counts or counts[0] < 1:
        raise ValueError(f"checkpoints must be positive step counts, got {checkpoints!r}")
    background = static_background(task, scene)
    bar = progress_bar(total=counts[-1], desc="steps", unit="step", enabled=progress)
    seconds = compiling = 0.0
    done = 0
    for target in counts:
        while done < target:
            n = min(PROGRESS_BLOCK, target - done)
            start, c0 = time.perf_counter(), compile_seconds()
            learner.train(frames, n, background)
            seconds += time.perf_counter() - start
            compiling += compile_seconds() - c0
            done += n
            bar.update(n)
        final, used = _final(scene, learner, background, ply if target == counts[-1] else None)
        yield target, SceneResult(
            settings={**task_settings(task), "steps": target}, psnr=final.psnr,
            ssim=final.ssim, depth_l1=final.depth_l1, seconds=seconds,
            seconds_per_frame=seconds / len(scene.train), peak_memory_mb=peak_memory_mb(),
            components_used=used, replay_bytes=int(learner.replay_bytes), early_views=None,
            early_psnr_when_seen=None, early_psnr_at_end=None, forgetting_curve=None,
            dropped=final.dropped, background_rgb=background.tolist(),
            uncovered=final.uncovered, seconds_compiling=compiling,
            images={"target": [f.rgb for f in scene.test], "render": final.renders},
            changes=change_scores(scene, final.renders))
    bar.close()
