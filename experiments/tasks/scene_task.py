"""The scene task: learn a 3-D splat from a stream of posed RGB-D frames, score held-out views.

The protocol (stream or static), evaluation and the run's record are in
:mod:`experiments.tasks.protocol`; the learners, chosen by ``task.method`` from
:data:`experiments.learners.LEARNERS`, in :mod:`experiments.learners`.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from experiments.tasks.check import (
    check_calibration,
    folder_findings,
    tum_reload,
    warn_inconsistent,
    warn_tiny_frames,
    within_trained_span,
)
from experiments.tasks.continual import check_segments
from experiments.tasks.depth_swap import depth_arrivals, simulated_network
from experiments.tasks.init_schemes import oracle_start
from experiments.learners import LEARNERS
from experiments.learners.gradient_learner import DEFAULT_CONFIG as BASELINE_CONFIG
from experiments.tasks.scene_report import warn_all
from experiments.tasks.protocol import (
    SceneResult,
    static_checkpoints,
    static_protocol,
    stream_protocol,
)
from experiments.tasks.sensor_swap import learned_surface, simulate_training_depth
from experiments.tasks.tracking import TrackedLearner, check_poses
from experiments.tasks.settings import (
    ASSIGN,
    AUTO_SCALE,
    COLOUR_RULE,
    DEPTH_KIND,
    DEPTH_REFERENCE,
    DRIFT_DEFAULT,
    ESTEP,
    SEARCH,
    FORMAT,
    INIT,
    MEASURED_BY,
    METHOD,
    OPACITY_RULE,
    ORDER,
    PROTOCOL,
    REPLAY_DEFAULT,
    SENSOR,
    SENSOR_HOLES_DEFAULT,
    valid_splat_scale,
)
from vbgs.baseline import TrainConfig
from vbgs.components import parse_components
from vbgs.data.changing import from_frame
from vbgs.data.doctor import refuse_bad_cameras
from vbgs.data.formats import detect_format, load_scene
from vbgs.data.scene import Scene, parse_size
from vbgs.data.sensor_record import data_sensor
from vbgs.data.streams import stream_order
from vbgs.data.synthetic import SCENES
from vbgs.inference import model
from vbgs.mapping import BudgetConfig, EvidenceConfig, GrowthConfig
from vbgs.render.background import parse_background
from vbgs.render.colour_fit import RIDGE as COLOUR_RIDGE
from vbgs.render.splats import VBGS_BLUR, VBGS_COV_SCALE, VBGS_OPACITY
from vbgs.sensors import HOLED_SENSORS, check_level, parse_holes


@dataclass(frozen=True)
class SceneTask:
    """Everything that defines one scene run."""

    scene: str = "object"
    format: str | None = FORMAT.default
    method: str = METHOD.default
    components: int | str = 20000  # K, or "auto" / "auto:MAX" (vbgs.components)
    frames: int = 60
    from_frame: int = 0  # the stream learned from this training frame on (a fresh map)
    n_test: int = 8
    n_val: int = 4  # validation views (tuning only: never scored by the protocol)
    size: int | tuple[int, int] = 128  # a square side, or (width, height): parse_size
    order: str = ORDER.default
    assign: str = ASSIGN.default
    estep: str = ESTEP.default
    candidates: int | None = None  # None: the sensor's default (8 exact, 16 measured)
    search: str = SEARCH.default  # VBGS: KD-tree or projective candidates
    # VBGS: the map saved after every frame to this .npz (vbgs.mapping.save), a stream
    # resumed from one (its frames already learned are skipped), and each stage's
    # seconds a frame in the record (vbgs.mapping.stages)
    save_map: str | None = None
    resume_map: str | None = None
    stage_times: bool = False
    # VBGS: the streaming bound in the record (vbgs.inference.bound; a second E-step of
    # every frame and the KL of every component, untimed but in the wall time: the room at
    # fit-scene's defaults took 26.5 s a run without it against 33.3 with it)
    streaming_bound: bool = False
    init: str = INIT.default  # see experiments.tasks.init_schemes
    seed: int = 0
    opacity_rule: str = OPACITY_RULE.default  # evidence (per component, vbgs.render.opacity) | constant
    opacity: float = VBGS_OPACITY  # the constant, with opacity_rule = "constant"
    # or "auto" (VBGS): chosen on the arrived training frames (vbgs.render.scale_fit)
    splat_scale: float | str = VBGS_COV_SCALE
    splat_blur: float = VBGS_BLUR  # px², the pixel filter VBGS splats are rendered with
    # VBGS splat colours: the posterior colour means | fitted to the training pixels
    # (vbgs.render.colour_fit; why off by default: experiments.tasks.settings.COLOUR_RULE)
    colour_rule: str = COLOUR_RULE.default
    colour_ridge: float = COLOUR_RIDGE  # pixels' worth of weight on the posterior colour (fit)
    depth_model: str | None = None
    depth_kind: str = DEPTH_KIND.default
    depth_preset: str | None = None
    depth_align: str = "auto"
    depth_reference: str = DEPTH_REFERENCE.default  # what aligns the model (depth.stream)
    # a depth sensor simulated on the training frames only (vbgs.sensors; test and
    # validation views keep their exact depth) and its noise multiplier (0: exact values)
    simulate_sensor: str = SENSOR.default
    sensor_level: float | None = None  # None: the data's (below), else 1
    # its holes: the sensor's own, or none / physical / random:RATE / physical+random:RATE
    # (vbgs.sensors.holes.parse_holes), apart from the level
    sensor_holes: str = SENSOR_HOLES_DEFAULT
    # how the training depth was measured, as the learners model it (VBGS:
    # vbgs.mapping.SensorConfig; the gradient baseline weights its depth L1 by 1/sigma);
    # None: the data's (vbgs.data.sensor_record.data_sensor: a folder's record, the
    # format's default, else exact), its level too when sensor_level is None
    sensor: str | None = MEASURED_BY.default
    background: str = "auto"  # auto (from pixels without depth, as frames arrive) | R,G,B
    # a dataset folder's camera and depth PNG scale instead of the folder's or the
    # format's (vbgs.data.calibration): (fx, fy, cx, cy) in pixels of the stored images
    intrinsics: tuple | None = None
    depth_scale: float | None = None
    # training poses: given | track | odometry (experiments.tasks.tracking), and the odometry's
    # drift per frame "SIGMA_T,SIGMA_R" (scene units, degrees; vbgs.tracking.drift)
    poses: str = "given"
    drift: str = DRIFT_DEFAULT
    # gradient baseline only (see experiments.learners.gradient_learner)
    replay: str = REPLAY_DEFAULT
    steps_per_frame: int = 50
    steps: int = 3000
    protocol: str = PROTOCOL.default
    # the continual-learning matrix over this many consecutive segments of the stream
    # (experiments.tasks.continual; 0: not measured; continual protocol only)
    cl_segments: int = 0
    # vbgs-polish only: weight of the posterior's anchor; None: by protocol
    # (experiments.learners.polish_learner.anchor_weight)
    polish_anchor: float | None = None
    # VBGS's method constants without a flag (frozen: safe to share); tune reaches each by
    # its dotted name (prior.cov_scale, growth.reach_cells, evidence.pass_sigmas)
    prior: model.PriorConfig = model.SURFACE_PRIOR
    growth: GrowthConfig = field(default_factory=GrowthConfig)
    evidence: EvidenceConfig = field(default_factory=EvidenceConfig)
    # a frame's point budget (vbgs.mapping.budget): --budget-points, budget.points in tune
    budget: BudgetConfig = field(default_factory=BudgetConfig)
    # the gradient baseline's constants (vbgs.baseline.TrainConfig: learning rates, depth
    # weight, densification), reached the same way (baseline.lr_means, baseline.depth_weight,
    # baseline.densify.every); its defaults: experiments.learners.gradient_learner
    baseline: TrainConfig = BASELINE_CONFIG

    def __post_init__(self):
        try:  # "640x480" (a TOML string) or [640, 480] become (640, 480)
            object.__setattr__(self, "size", parse_size(self.size))
        except ValueError as err:
            raise ValueError(f"size: {err}") from None
        if parse_components(self.components)[0] and (self.method == "gradient"
                                                     or self.init != "stream"):
            which = (f"--method {self.method}" if self.method == "gradient"
                     else f"--init {self.init}")
            raise ValueError(f"components {self.components!r} is chosen by VBGS as frames "
                             f"arrive (--init stream); {which} takes a number of "
                             f"components: give one")
        self._resolve_sensor()
        for name in ("frames", "steps_per_frame", "steps"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if not isinstance(self.from_frame, int) or not 0 <= self.from_frame < self.frames:
            raise ValueError(f"from_frame must be 0 to {self.frames - 1}, got {self.from_frame!r}")
        if not isinstance(self.n_val, int) or self.n_val < 0:
            raise ValueError(f"n_val must be a non-negative integer, got {self.n_val!r}")
        for name, choice in (("method", METHOD), ("protocol", PROTOCOL), ("order", ORDER),
                             ("assign", ASSIGN), ("estep", ESTEP), ("format", FORMAT),
                             ("search", SEARCH),
                             ("depth_kind", DEPTH_KIND), ("opacity_rule", OPACITY_RULE),
                             ("depth_reference", DEPTH_REFERENCE),
                             ("colour_rule", COLOUR_RULE), ("simulate_sensor", SENSOR),
                             ("sensor", MEASURED_BY)):
            choice.check(name, getattr(self, name))
        try:
            check_level(self.sensor_level)
        except ValueError:
            raise ValueError(f"sensor_level must be a finite number >= 0 (0: exact depth "
                             f"values, 1: the published sensor model, 2: twice its noise), "
                             f"got {self.sensor_level!r}") from None
        try:
            holes = parse_holes(self.sensor_holes)
        except ValueError as err:
            raise ValueError(f"sensor_holes: {err}") from None
        if not holes.own and self.simulate_sensor not in HOLED_SENSORS:
            raise ValueError(f"sensor_holes {self.sensor_holes!r} sets the holes of a simulated "
                             f"sensor, but simulate_sensor {self.simulate_sensor!r} makes none; "
                             f"simulate one of {', '.join(HOLED_SENSORS)}, or leave the holes "
                             f"at {SENSOR_HOLES_DEFAULT!r}")
        if self.simulate_sensor != "exact" and self.depth_model:
            raise ValueError(f"simulate_sensor {self.simulate_sensor!r} and depth_model both "
                             f"replace the training depth; give one of them")
        check_segments(self.cl_segments, self.frames)
        if self.depth_model and self.init != "stream":
            raise ValueError(f"init {self.init!r} reads the whole stream's points before it "
                             f"starts, but with a depth_model the depth exists only as "
                             f"frames arrive; use init 'stream'")
        oracle_start(self.init)  # a known scheme
        check_calibration(self)
        check_poses(self)
        parse_background(self.background)  # fails on a malformed R,G,B
        if self.splat_scale == AUTO_SCALE and self.method != "vbgs":
            raise ValueError(f"splat_scale 'auto' is chosen by VBGS on the frames it learned; "
                             f"--method {self.method} takes a number")
        if not valid_splat_scale(self.splat_scale):
            raise ValueError(f"splat_scale must be a positive number or 'auto', got "
                             f"{self.splat_scale!r}")
        if not (isinstance(self.splat_blur, (int, float)) and 0 <= self.splat_blur < 10):
            raise ValueError(f"splat_blur must be a pixel filter variance in [0, 10) px², "
                             f"got {self.splat_blur!r}")
        if self.polish_anchor is not None and not (
                isinstance(self.polish_anchor, (int, float)) and self.polish_anchor >= 0):
            raise ValueError(f"polish_anchor must be a number >= 0 (0: a free polish), "
                             f"got {self.polish_anchor!r}")
        if not self.colour_ridge > 0:
            raise ValueError(f"colour_ridge must be > 0 (pixels' worth of weight on the "
                             f"posterior colour), got {self.colour_ridge!r}")

    def _resolve_sensor(self) -> None:
        """``sensor`` and ``sensor_level`` left None become the data's (a folder's
        record, its format's default; a level the record does not give is 1); a
        simulated sensor on a folder whose record says its training depth already came
        from one is refused."""
        data = data_sensor(self.scene, self.format)
        if self.sensor is None:
            object.__setattr__(self, "sensor", data.sensor)
        if self.sensor_level is None:
            object.__setattr__(self, "sensor_level",
                               data.level if self.sensor == data.sensor else 1.0)
        if self.simulate_sensor != "exact" and data.recorded and data.sensor != "exact":
            raise ValueError(f"scene {self.scene}: its training depth was measured by "
                             f"{data.sensor!r} already ({data.source}); simulating "
                             f"{self.simulate_sensor!r} on top of it would corrupt it twice: "
                             f"drop --simulate-sensor (the folder's sensor is the default "
                             f"--sensor)")


def load_task_scene(task: SceneTask) -> Scene:
    """The scene of a task at the task's size and frame counts, with at most
    ``task.n_val`` validation views (synthetic: extra views drawn like the test views;
    datasets: their validation split, see :mod:`vbgs.data.formats`)."""
    if task.scene in SCENES and not Path(task.scene).is_dir():
        scene = load_scene(task.scene, size=task.size, n_train=task.frames, n_test=task.n_test,
                           seed=task.seed, n_val=task.n_val)
        warn_tiny_frames(scene, task.scene)
        return scene
    given = {k: v for k in ("intrinsics", "depth_scale") if (v := getattr(task, k)) is not None}
    if task.depth_model and Path(task.scene).is_dir() and (
            task.format or detect_format(task.scene)) == "blender":
        given["require_depth"] = False  # RGB-only: the depth model gives it as frames arrive
    scene = load_scene(task.scene, format=task.format, size=task.size, **given)
    refuse_bad_cameras(scene.train + scene.test + scene.val,
                       scene.record.get("depth_scale"), f"scene {task.scene!r}")
    warn_tiny_frames(scene, task.scene)
    scene = within_trained_span(folder_findings(scene, task.scene), task.frames)
    scene = scene._replace(train=scene.train[: task.frames], test=scene.test[: task.n_test],
                           val=scene.val[: task.n_val])
    if Path(task.scene).is_dir():  # a dataset folder (a real scene by name is one view)
        fmt = task.format or detect_format(task.scene)
        if any(np.any(f.depth > 0) for f in scene.train):  # RGB-only: nothing to compare
            warn_inconsistent(scene, fmt, task.scene, tum_reload(
                task.scene, fmt, task.size, given, task.frames))
        scene = scene._replace(record={"format": fmt, **scene.record})
    return scene


def prepare_scene(task) -> tuple[Scene, dict]:
    """The task's scene with the depth of its simulated sensor on its training frames
    (exact: the scene's own), cut to what the learner's sensor model takes as surface,
    and the report. A task with a depth model gets its training depth as the frames
    arrive (:func:`experiments.tasks.depth_swap.depth_arrivals`), not here; a simulated
    depth network's is cut there, once made metric. Test and validation views keep their
    depth."""
    scene = from_frame(load_task_scene(task), task.from_frame)
    if task.depth_model:
        return scene, {}
    scene, report = simulate_training_depth(scene, task.simulate_sensor, task.sensor_level,
                                            task.seed, task.sensor_holes)
    if simulated_network(task):  # cut once made metric, as frames arrive (depth_arrivals)
        return scene, report
    if task.simulate_sensor == "exact" and Path(task.scene).is_dir():  # a folder's own depth
        data = data_sensor(task.scene, task.format)
        report = {**report, "depth_sensor": data.sensor, "depth_sensor_level": data.level,
                  **data.measured}  # a record's holes and error: over the frames written
    return learned_surface(scene, report, task.sensor, task.sensor_level)


def warn_rgb_only_tests(scene: Scene) -> bool:
    """Say on stderr, once, when no test view has depth (an RGB-only folder): the views
    are scored on RGB alone and depth L1 is absent. True when so."""
    if any(np.any(f.depth > 0) for f in scene.test):
        return False
    print(f"note: none of the {len(scene.test)} test views has depth: they are scored on "
          f"RGB alone (PSNR, SSIM); depth_l1 is absent", file=sys.stderr)
    return True


def run_scene(task: SceneTask, *, progress: bool = False, ply: str | None = None) -> SceneResult:
    """Run the task's learner on its scene under the task's protocol and score the
    held-out views (a learner that only streams, VBGS, streams under either protocol)."""
    run = _SceneRun(task)
    if run.static:
        result = static_protocol(task, run.scene, run.learner,
                                 run.learner.static_frames(run.scene), progress=progress,
                                 ply=ply)
    else:
        result = stream_protocol(task, run.scene, run.learner, progress=progress, ply=ply,
                                 arrive=run.arrivals)
    return run.finish(result)


def run_scene_checkpoints(task: SceneTask, checkpoints, *, progress: bool = False):
    """A static run of ``task`` to the largest of ``checkpoints`` (step counts; the
    task's ``steps`` is not read), yielding ``(steps, SceneResult)`` at each: the result
    :func:`run_scene` gives for ``steps`` steps (the learners' schedules are per step,
    :func:`experiments.tasks.protocol.static_checkpoints`), ``seconds`` the training to that
    count. The warnings are said once, at the last."""
    if task.protocol != "static" or "static" not in LEARNERS[task.method].PROTOCOLS:
        raise ValueError(f"checkpoints are steps of a static run: --method {task.method} "
                         f"--protocol {task.protocol} takes none")
    run = _SceneRun(task)
    frames = run.learner.static_frames(run.scene)
    last = max(checkpoints)
    for n, result in static_checkpoints(task, run.scene, run.learner, frames, checkpoints,
                                        progress=progress):
        yield n, run.finish(result, warn=n == last)


class _SceneRun:
    """A task's scene, depth and learner, built and checked before any training
    (:func:`run_scene`), and the record finished from a protocol's result."""

    def __init__(self, task: SceneTask):
        learner_cls = LEARNERS[task.method]
        learner_cls.check(task)  # bad settings fail before any work
        scene, self.depth_report = prepare_scene(task)
        if not scene.test:
            raise ValueError(f"scene {task.scene!r} has no held-out test views to score a "
                             f"learner on ({len(scene.train)} training view(s)); use it with "
                             f"the oracle command, or pick a scene with more views")
        if len(scene.train) == 1:
            print(f"warning: scene {task.scene!r} has one training frame: a map from one view "
                  f"scores poorly on held-out views seen from elsewhere", file=sys.stderr)
        self.rgb_only_tests = warn_rgb_only_tests(scene)
        self.static = task.protocol == "static" and "static" in learner_cls.PROTOCOLS
        order = (np.arange(len(scene.train)) if self.static
                 else stream_order(len(scene.train), task.order, seed=task.seed))
        self.arrivals = depth_arrivals(task, scene, order, self.depth_report)
        if self.static and self.arrivals is not None:  # all frames at once, in file order
            scene = scene._replace(train=list(self.arrivals(iter(scene.train))))
        learner = learner_cls(task, scene)
        if task.poses != "given":  # fed the poses it tracks (the first given)
            learner = TrackedLearner(learner, task, scene)
        self.task, self.scene, self.learner = task, scene, learner

    def finish(self, result: SceneResult, *, warn: bool = True) -> SceneResult:
        """The result with the depth report, the learner's details and what ran; the
        warnings on stderr when ``warn``."""
        task = self.task
        depth_report = self.depth_report
        if self.arrivals is not None:
            depth_report = {**depth_report, **self.arrivals.report()}
        details = self.learner.details(result)
        if warn:
            warn_all(details, task, result.uncovered,
                     (result.early_psnr_when_seen, result.early_psnr_at_end))
        return replace(result, depth=depth_report, details=details,
                       depth_l1=None if self.rgb_only_tests else result.depth_l1,
                       settings={**result.settings, **what_ran(task, self.scene)})


def what_ran(task: SceneTask, scene: Scene) -> dict:
    """The frame and view counts that ran (a dataset may hold fewer than were asked
    for): ``frames``, ``n_test``, ``n_val``, and what was asked where it differs."""
    ran = {"frames": len(scene.train), "n_test": len(scene.test), "n_val": len(scene.val)}
    asked = {f"{name}_asked": getattr(task, name) for name, n in ran.items()
             if getattr(task, name) != n}
    camera = {}
    if scene.record:  # a dataset folder: the camera as run (pixel centres at col + 0.5)
        cam = scene.train[0].camera
        camera = {"intrinsics": [float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy)],
                  "image_size": [int(cam.width), int(cam.height)]}
    data = data_sensor(task.scene, task.format)
    sensor = {"sensor_from": "given" if task.sensor != data.sensor else data.source}
    return {**ran, **asked, **camera, **scene.record, **sensor}
