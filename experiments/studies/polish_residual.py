"""Where the continual polish gains or loses against VBGS: its residual taken apart, scored
on validation views.

    python -m experiments.studies.polish_residual --scene object --replay none [--val-views 8]

streams the task's frames through :class:`experiments.learners.PolishLearner` (continual,
``--steps-per-frame``, default 10) and, at the end, scores on the scene's first N
validation views (never its test views) VBGS's splats, the polished ones, and splats
between them: VBGS's with one group of the polish's residual added (``only``), the
polish with one group's residual taken away (``without``), the groups being the means,
the covariances (scales and rotations), the colours and the opacities, and the means'
residual cut into its part along each splat's thin axis (its normal) and the rest. Prints
one JSON record. This is how the polish's no-replay loss against VBGS was traced to the
means' steps along the normals (:mod:`experiments.learners.polish_learner`, "Why the
polish without replay went below VBGS").
"""

from __future__ import annotations

import argparse
import sys

import jax.numpy as jnp

from experiments.learners import PolishLearner
from experiments.cli.output import dumps
from experiments.provenance import record_command, stamp
from experiments.tasks.protocol import evaluate, stream_frames
from experiments.tasks.scene_task import SceneTask, prepare_scene
from vbgs.baseline import to_splats
from vbgs.baseline.params import Params
from vbgs.data.streams import stream_order
from vbgs.render.splats import rotations_from_quaternions

GROUPS = {"means": ("means",), "covariances": ("log_scales", "rotations"),
          "colours": ("colour_logits",), "opacities": ("opacity_logits",)}


def thin_axis_part(polished: Params, base: Params) -> jnp.ndarray:
    """The means' residual ``[K, 3]`` projected on each base splat's thin axis."""
    rot = rotations_from_quaternions(base.rotations)  # [K, 3, 3], columns: axes
    thin = jnp.argmin(base.log_scales, axis=-1)  # [K]
    axis = jnp.take_along_axis(rot, thin[:, None, None], axis=2)[..., 0]  # [K, 3]
    residual = polished.means - base.means
    return axis * jnp.sum(axis * residual, -1, keepdims=True)


def variants(polished: Params, base: Params) -> dict[str, Params]:
    """The splats scored: VBGS, the polish, and the residual's parts (module docstring)."""
    out = {"vbgs": base, "polish": polished}
    for name, fields in GROUPS.items():
        out[f"only {name}"] = base._replace(**{f: getattr(polished, f) for f in fields})
        out[f"without {name}"] = polished._replace(**{f: getattr(base, f) for f in fields})
    normal = thin_axis_part(polished, base)
    out["only means along the thin axis"] = base._replace(means=base.means + normal)
    out["without means along the thin axis"] = polished._replace(means=polished.means - normal)
    return out


def run(task: SceneTask) -> dict:
    """The record: each variant's PSNR over the validation views, and per view."""
    scene, _ = prepare_scene(task)
    if not scene.val:
        raise ValueError(f"scene {task.scene!r} has no validation views: give --val-views >= 1")
    learner = PolishLearner(task, scene)
    background = None
    for _, frame, background in stream_frames(task, scene,
                                              stream_order(len(scene.train), task.order,
                                                           seed=task.seed)):
        learner.learn(frame, background)
    scores = {}
    for name, params in variants(learner.state.params, learner._base).items():
        ev = evaluate(to_splats(params), scene.val, background, learner.blur)
        scores[name] = {"psnr": ev.psnr, "view_psnr": [float(v) for v in ev.view_psnr]}
    return {"scene": task.scene, "replay": task.replay, "val_views": len(scene.val),
            "steps_per_frame": task.steps_per_frame, "scores": scores}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.studies.polish_residual",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="object")
    parser.add_argument("--replay", default="none")
    parser.add_argument("--val-views", type=int, default=8)
    parser.add_argument("--steps-per-frame", type=int, default=10)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--components", type=int, default=20000)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    record_command(sys.argv[1:] if argv is None else list(argv), parser.prog)
    task = SceneTask(scene=args.scene, method="vbgs-polish", protocol="continual",
                     replay=args.replay, steps_per_frame=args.steps_per_frame,
                     n_val=args.val_views, size=args.size, components=args.components,
                     frames=args.frames, seed=args.seed)
    print(dumps(stamp(run(task))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
