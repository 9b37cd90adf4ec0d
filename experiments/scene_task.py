"""The scene task: learn a 3-D splat from a stream of posed RGB-D frames, score held-out views.

The protocol (stream or static), evaluation and the run's record are in
:mod:`experiments.protocol`; the learners, chosen by ``task.method`` from
:data:`experiments.learners.LEARNERS`, in :mod:`experiments.learners`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from experiments.init_schemes import oracle_start
from experiments.learners import LEARNERS, METHODS
from experiments.protocol import SceneResult, static_protocol, stream_protocol
from vbgs import model
from vbgs.background import parse_background
from vbgs.data.formats import load_scene
from vbgs.data.scene import Scene
from vbgs.colour_fit import RIDGE as COLOUR_RIDGE
from vbgs.splats import VBGS_COV_SCALE, VBGS_OPACITY

PROTOCOLS = ("continual", "static")
OPACITY_RULES = ("evidence", "constant")
COLOUR_RULES = ("fit", "posterior")


@dataclass(frozen=True)
class SceneTask:
    """Everything that defines one scene run."""

    scene: str = "object"
    format: str | None = None
    method: str = "vbgs"
    components: int = 20000
    frames: int = 60
    n_test: int = 8
    n_val: int = 4  # validation views (tuning only: never scored by the protocol)
    size: int = 128
    order: str = "sequential"
    assign: str = "prior"
    estep: str = "sparse"
    candidates: int = 16
    init: str = "stream"  # stream | data | random (see experiments.init_schemes)
    seed: int = 0
    opacity_rule: str = "evidence"  # evidence (per component, vbgs.opacity) | constant
    opacity: float = VBGS_OPACITY  # the constant, with opacity_rule = "constant"
    splat_scale: float = VBGS_COV_SCALE
    # VBGS splat colours: fitted to the training pixels (vbgs.colour_fit) | the posterior
    # colour means. Chosen on validation views by `python -m experiments.run tune`.
    colour_rule: str = "fit"
    colour_ridge: float = COLOUR_RIDGE  # pixels' worth of weight on the posterior colour (fit)
    depth_model: str | None = None
    depth_kind: str = "inverse"
    depth_preset: str | None = None
    depth_align: str = "auto"
    background: str = "auto"  # auto (from pixels without depth, as frames arrive) | R,G,B
    # gradient baseline only (see experiments.learners.gradient_learner)
    replay: str = "none"
    steps_per_frame: int = 50
    steps: int = 3000
    protocol: str = "continual"  # continual | static
    # VBGS: skip points explained within this many nats (None: learn every point; vbgs.skip)
    skip_margin: float | None = None
    prior: model.PriorConfig = field(default_factory=model.PriorConfig)

    def __post_init__(self):
        for name in ("components", "frames", "size", "steps_per_frame", "steps"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if not isinstance(self.n_val, int) or self.n_val < 0:
            raise ValueError(f"n_val must be a non-negative integer, got {self.n_val!r}")
        if self.method not in METHODS:
            raise ValueError(f"unknown method {self.method!r}: use one of {METHODS}")
        oracle_start(self.init)  # a known scheme
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"unknown protocol {self.protocol!r}: use one of {PROTOCOLS}")
        parse_background(self.background)  # fails on a malformed R,G,B
        if self.opacity_rule not in OPACITY_RULES:
            raise ValueError(f"unknown opacity rule {self.opacity_rule!r}: use one of "
                             f"{OPACITY_RULES}")
        if not self.colour_ridge > 0:
            raise ValueError(f"colour_ridge must be > 0 (pixels' worth of weight on the "
                             f"posterior colour), got {self.colour_ridge!r}")
        if self.colour_rule not in COLOUR_RULES:
            raise ValueError(f"unknown colour rule {self.colour_rule!r}: use one of "
                             f"{COLOUR_RULES}")


def load_task_scene(task: SceneTask) -> Scene:
    """The scene of a task at the task's size and frame counts, with at most
    ``task.n_val`` validation views (synthetic: extra views drawn like the test views;
    datasets: their validation split, see :mod:`vbgs.data.formats`)."""
    if task.scene in ("object", "room") and not Path(task.scene).is_dir():
        return load_scene(task.scene, size=task.size, n_train=task.frames, n_test=task.n_test,
                          seed=task.seed, n_val=task.n_val)
    scene = load_scene(task.scene, format=task.format, size=task.size)
    return scene._replace(train=scene.train[: task.frames], test=scene.test[: task.n_test],
                          val=scene.val[: task.n_val])


def prepare_scene(task) -> tuple[Scene, dict]:
    """The task's scene, with estimated depth on its training frames if the task names
    a depth model (the report of the estimation is returned alongside)."""
    scene = load_task_scene(task)
    if not task.depth_model:
        return scene, {"depth_source": "sensor"}
    from experiments.depth_swap import estimate_scene_depth

    return estimate_scene_depth(scene, task.depth_model, kind=task.depth_kind,
                                preset=task.depth_preset, align_method=task.depth_align,
                                seed=task.seed)


def run_scene(task: SceneTask, *, progress: bool = False, ply: str | None = None) -> SceneResult:
    """Run the task's learner on its scene under the task's protocol and score the
    held-out views (a learner that only streams, VBGS, streams under either protocol)."""
    learner_cls = LEARNERS[task.method]
    learner_cls.check(task)  # bad settings fail before any work
    scene, depth_report = prepare_scene(task)
    learner = learner_cls(task, scene)
    if task.protocol == "static" and "static" in learner_cls.PROTOCOLS:
        result = static_protocol(task, scene, learner, learner.static_frames(scene),
                                 progress=progress, ply=ply)
    else:
        result = stream_protocol(task, scene, learner, progress=progress, ply=ply)
    return replace(result, depth=depth_report, details=learner.details(result))


def save_views(path: str | Path, targets, renders, title: str, n: int = 4) -> None:
    """Ground truth (top) and render (bottom) of up to ``n`` held-out views in one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = min(n, len(targets))
    fig, axes = plt.subplots(2, n, figsize=(2.6 * n, 5.4), squeeze=False)
    for j in range(n):
        for i, (im, name) in enumerate(((targets[j], "ground truth"), (renders[j], "render"))):
            axes[i, j].imshow(np.clip(im, 0, 1))
            axes[i, j].set_title(f"{name}, view {j}", fontsize=9)
            axes[i, j].axis("off")
    fig.suptitle(title)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
