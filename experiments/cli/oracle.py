"""``oracle``: render splats built from a view's ground truth (the renderer's check, apart
from any learner)."""

from __future__ import annotations

from experiments.cli.options import add_frames, add_json, add_scene_size, add_seed
from experiments.tasks.settings import FORMAT, add_choice


def add(sub):
    p = sub.add_parser("oracle", help="splats from a view's ground truth, rendered back (the "
                                      "renderer's check, apart from any learner)")
    p.add_argument("--scene", default="object",
                   help="object | room | walk | motorcycle (one real RGB-D view) | a dataset folder")
    add_choice(p, "--format", FORMAT)
    add_frames(p)
    add_scene_size(p)
    p.add_argument("--view", type=int, default=0, help="source training frame")
    add_seed(p)
    add_json(p)


def run(args) -> dict:
    from dataclasses import asdict

    from experiments.studies.oracle import oracle_score
    from experiments.tasks.scene_task import SceneTask, load_task_scene

    task = SceneTask(scene=args.scene, format=args.format, frames=args.frames, n_test=1,
                     size=args.size, seed=args.seed)
    return {"scene": args.scene, **asdict(oracle_score(load_task_scene(task), args.view))}
