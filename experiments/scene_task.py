"""The scene task: learn a 3-D splat from a stream of posed RGB-D frames, score held-out views.

Protocol (the same for every method, so tables compare like with like):

* training frames arrive one at a time in the chosen ``order``; nothing is replayed
  unless the method has a replay buffer;
* **early views** are the held-out test views nearest (camera centre) to the first 10%
  of the streamed frames; their mean PSNR is measured right after those frames were
  learned (``early_psnr_when_seen``) and at the end (``early_psnr_at_end``), and along
  the stream (``forgetting_curve``): the forgetting they suffer;
* final metrics are over all test views: PSNR, SSIM, depth L1 (where the ground truth
  has depth; rendered depth is the alpha-normalised expected depth).
"""

from __future__ import annotations

import resource
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import jax
import numpy as np
from tqdm.auto import tqdm

from vbgs import model
from vbgs.camera import unproject
from vbgs.data.formats import load_scene
from vbgs.data.scene import Frame, Scene
from vbgs.data.streams import stream_order
from vbgs.metrics import depth_l1, psnr, ssim
from vbgs.raster import rasterize
from vbgs.stepper import Stepper
from vbgs.splats import VBGS_COV_SCALE, VBGS_OPACITY, Splats, from_posterior, save_ply

EARLY_FRACTION = 0.1  # the first 10% of the stream defines the "early" views
CURVE_POINTS = 10  # evaluations of the early views along the stream
ALPHA_FOR_DEPTH = 0.5  # rendered depth counts only where the splats cover the pixel


@dataclass(frozen=True)
class SceneTask:
    """Everything that defines one scene run."""

    scene: str = "object"
    format: str | None = None
    method: str = "vbgs"
    components: int = 20000
    frames: int = 60
    n_test: int = 8
    size: int = 128
    order: str = "sequential"
    assign: str = "prior"
    estep: str = "sparse"
    candidates: int = 16
    init: str = "random"
    seed: int = 0
    opacity: float = VBGS_OPACITY
    splat_scale: float = VBGS_COV_SCALE
    depth_model: str | None = None
    depth_kind: str = "inverse"
    depth_preset: str | None = None
    depth_align: str = "auto"
    # gradient baseline only (see experiments.gradient_task)
    replay: str = "none"
    steps_per_frame: int = 50
    steps: int = 3000
    protocol: str = "continual"  # continual | static
    prior: model.PriorConfig = field(default_factory=model.PriorConfig)

    def __post_init__(self):
        for name in ("components", "frames", "size", "steps_per_frame", "steps"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if self.method not in ("vbgs", "gradient"):
            raise ValueError(f"unknown method {self.method!r}: use 'vbgs' or 'gradient'")


def load_task_scene(task: SceneTask) -> Scene:
    """The scene of a task at the task's size and frame counts."""
    if task.scene in ("object", "room") and not Path(task.scene).is_dir():
        return load_scene(task.scene, size=task.size, n_train=task.frames, n_test=task.n_test,
                          seed=task.seed)
    scene = load_scene(task.scene, format=task.format, size=task.size)
    return scene._replace(train=scene.train[: task.frames], test=scene.test[: task.n_test])


def early_views(scene: Scene, order: np.ndarray) -> list[int]:
    """Test views nearest (camera centre) to the first EARLY_FRACTION of the stream."""
    n_early = max(1, int(round(EARLY_FRACTION * len(order))))
    early_pos = np.stack([scene.train[i].camera.position for i in order[:n_early]])
    test_pos = np.stack([f.camera.position for f in scene.test])
    nearest = np.linalg.norm(test_pos[:, None] - early_pos[None], axis=-1).argmin(0)
    return sorted(set(int(i) for i in nearest))


def render_view(splats: Splats, frame: Frame, background) -> tuple[np.ndarray, np.ndarray, int]:
    """Render one view: rgb ``[h, w, 3]``, alpha-normalised depth ``[h, w]`` (0 where
    uncovered) and the number of splats the tiles dropped."""
    out = rasterize(splats, frame.camera, background=background)
    alpha = np.asarray(out.alpha)
    depth = np.where(alpha > ALPHA_FOR_DEPTH, np.asarray(out.depth) / np.maximum(alpha, 1e-6), 0)
    return np.clip(np.asarray(out.rgb), 0, 1), depth, int(out.dropped)


def evaluate(splats: Splats, frames: list[Frame], background) -> dict:
    """Mean PSNR, SSIM and depth L1 over ``frames``, plus the renders."""
    scores, renders, dropped = [], [], 0
    for frame in frames:
        rgb, depth, n = render_view(splats, frame, background)
        dropped += n
        scores.append((psnr(rgb, frame.rgb), ssim(rgb, frame.rgb), depth_l1(depth, frame.depth)))
        renders.append(rgb)
    psnrs, ssims, l1s = np.asarray(scores).T
    return {"psnr": float(psnrs.mean()), "ssim": float(ssims.mean()),
            "depth_l1": float(np.nanmean(l1s)) if np.isfinite(l1s).any() else float("nan"),
            "dropped": dropped, "renders": renders}


def frame_points(frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """Coloured world points of a frame's valid depth."""
    return unproject(frame.camera, frame.rgb, frame.depth)


def peak_memory_mb() -> float:
    """Peak resident memory of this process so far (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class VbgsLearner:
    """VBGS as a continual learner: each arriving frame is one :func:`vbgs.model.update`."""

    replay_bytes = 0

    def __init__(self, task: SceneTask, scene: Scene):
        self.task = task
        xyz, rgb = (np.concatenate(a) for a in zip(*map(frame_points, scene.train), strict=True))
        key = jax.random.key(task.seed)
        self.prior = model.init(xyz, rgb, task.components, key=key, scheme=task.init,
                                config=task.prior, bounds=scene.bounds)
        self.state = model.start(self.prior)
        self.step = Stepper(self.prior, assign=task.assign, config=task.prior, estep=task.estep,
                            n_candidates=task.candidates)

    def learn(self, frame: Frame) -> None:
        xyz, rgb = frame_points(frame)
        self.state, _ = self.step(self.state, xyz, rgb)
        jax.block_until_ready(self.state.stats.count)

    def splats(self, drop_unused: bool = False) -> Splats:
        return from_posterior(self.state.posterior, self.prior, opacity=self.task.opacity,
                              cov_scale=self.task.splat_scale, drop_unused=drop_unused)


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


def stream_protocol(task, scene: Scene, learner, *, progress: bool = False,
                    ply: str | None = None) -> dict:
    """Feed the training frames to ``learner`` one at a time in the task's order,
    tracking the early views, then score every test view (see the module docstring).

    ``learner`` has ``learn(frame)``, ``splats(drop_unused=False) -> Splats`` and
    ``replay_bytes``; the same protocol serves VBGS and the gradient baseline.
    """
    order = stream_order(len(scene.train), task.order, seed=task.seed)
    early_idx = early_views(scene, order)
    early = [scene.test[i] for i in early_idx]
    n_early = max(1, int(round(EARLY_FRACTION * len(order))))
    checkpoints = set(np.linspace(n_early, len(order), CURVE_POINTS).round().astype(int))
    curve, frame_seconds = [], []
    for step, i in enumerate(tqdm(order, desc="frames", disable=not progress, leave=False), 1):
        t0 = time.perf_counter()
        learner.learn(scene.train[i])
        frame_seconds.append(time.perf_counter() - t0)
        if step in checkpoints:
            curve.append([step, evaluate(learner.splats(), early, scene.background)["psnr"]])
    final = evaluate(learner.splats(), scene.test, scene.background)
    kept = learner.splats(drop_unused=True)
    if ply:
        save_ply(ply, kept)
    steady = frame_seconds[2:] or frame_seconds  # the first frames include compilation
    return {
        "psnr": final["psnr"],
        "ssim": final["ssim"],
        "depth_l1": final["depth_l1"],
        "seconds": float(np.sum(frame_seconds)),
        "seconds_per_frame": float(np.mean(steady)),
        "peak_memory_mb": peak_memory_mb(),
        "components_used": kept.count,
        "replay_bytes": int(learner.replay_bytes),
        "early_views": early_idx,
        "early_psnr_when_seen": curve[0][1],
        "early_psnr_at_end": curve[-1][1],
        "forgetting_curve": curve,
        "dropped": final["dropped"],
        "images": {"target": [f.rgb for f in scene.test], "render": final["renders"]},
    }


def task_settings(task) -> dict:
    """The task's settings as a flat dict (hyperparameter objects left out)."""
    settings = asdict(task)
    settings.pop("prior", None)
    return settings


def run_scene(task: SceneTask, *, progress: bool = False, ply: str | None = None) -> dict:
    """Stream the training frames through the task's method and score the held-out views."""
    if task.method == "gradient":
        from experiments.gradient_task import run_gradient_scene

        return run_gradient_scene(task, progress=progress, ply=ply)
    scene, depth_report = prepare_scene(task)
    learner = VbgsLearner(task, scene)
    result = stream_protocol(task, scene, learner, progress=progress, ply=ply)
    return {**task_settings(task), **depth_report, **result}


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
