"""``depth-study``: sensor depth against estimated depth (the RGB-only path), per method."""

from __future__ import annotations

from experiments.cli.options import add_frames, add_json, add_scene
from experiments.tasks.settings import METHOD


def add(sub):
    p = sub.add_parser("depth-study", help="sensor vs estimated depth (ONNX test model)")
    # defaults: the settings of the committed results/depth_study (minutes on 2 cores)
    add_scene(p)
    p.add_argument("--components", type=int, default=5000)
    add_frames(p, default=30)
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--methods", nargs="+", choices=METHOD.values, default=["vbgs", "gradient"])
    p.add_argument("--steps-per-frame", type=int, default=50, help="gradient, continual")
    p.add_argument("--out", default="runs/depth_study",
                   help="output folder (default runs/depth_study, ignored by git)")
    add_json(p)


def run(args) -> dict:
    from experiments.benchmarks.bench import write_table
    from experiments.studies.depth_study import (
        require_onnx,
        run_depth_study,
        study_command,
        study_settings,
    )

    require_onnx()  # before any work

    task_kw = dict(scene=args.scene, components=args.components, frames=args.frames,
                   size=args.size, steps_per_frame=args.steps_per_frame)
    rows = run_depth_study(args.out, methods=args.methods, progress=True,
                           **task_kw)
    paths = write_table(rows, args.out, "depth_study",
                        command=study_command(task_kw, args.methods, args.out),
                        settings=study_settings(task_kw, args.methods))
    return {"rows": rows, "files": [str(p) for p in paths]}
