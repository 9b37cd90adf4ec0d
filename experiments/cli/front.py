"""``front``: run time and memory against error (VBGS, VBGS-polish and the gradient
baseline at several step counts); CSV, markdown and a PNG."""

from __future__ import annotations

from experiments.cli.options import SCENE_HELP, add_frames, add_json, add_seed, add_test_views
from experiments.cli.output import check_fewer_components
from experiments.tasks.settings import FORMAT, add_choice


def add(sub):
    p = sub.add_parser("front", help="PSNR / SSIM / depth L1 against wall time and replay "
                                     "memory: VBGS, VBGS-polish and the gradient baseline at "
                                     "several step counts; CSV, markdown and a PNG")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--scene", help=SCENE_HELP)
    what.add_argument("--image", help="a bundled photo or an image file: VBGS against the "
                                      "2-D gradient baseline")
    what.add_argument("--replot", metavar="CSV", help="draw a front's PNG again from its "
                      "CSV (beside it), running nothing")
    p.add_argument("--title", default=None, help="--replot: the plot's title (default: "
                   "the CSV's title column)")
    add_choice(p, "--format", FORMAT)
    p.add_argument("--size", type=int, default=None,
                   help="image size (default: 128 for scenes, 256 for images)")
    p.add_argument("--components", default=None, metavar="K[,K...]",
                   help="components / splats (default: 20000 for scenes; 2000,8000,16000 "
                        "for images); scenes take one count")
    add_frames(p)
    add_test_views(p)
    add_seed(p)
    p.add_argument("--polish-steps", default="30,100,300,900", metavar="N,N",
                   help="vbgs-polish static step counts")
    p.add_argument("--gradient-steps", default=None, metavar="N,N",
                   help="gradient step counts (default: 100,300,900,3000 for scenes, "
                        "100,300,1000,3000 for images)")
    p.add_argument("--replays", default="none,fifo:8",
                   help="continual rows: replay buffers, comma-separated ('' for none)")
    p.add_argument("--steps-per-frame", type=int, default=20, help="continual rows")
    p.add_argument("--iters", type=int, default=10, help="images: VBGS's CAVI iterations")
    p.add_argument("--out", default=None, help="folder for NAME.csv, .md and .png "
                   "(default runs/front/NAME, ignored by git)")
    add_json(p)


def run(args) -> dict:
    from pathlib import Path

    from experiments.studies.front import FrontPlan, parse_counts, write_front

    if args.replot:
        from experiments.studies.front import plot_front, read_front

        csv = Path(args.replot)
        if not csv.is_file():
            raise ValueError(f"--replot {csv}: no such CSV (a front's NAME.csv)")
        rows = read_front(csv)
        title = args.title or str(rows[0].get("title", csv.stem))
        plot_front(rows, csv.with_suffix(".png"), title)
        return {"files": [str(csv.with_suffix(".png"))]}
    name = Path(args.scene or args.image).name or "front"
    out = Path(args.out or Path("runs/front") / name)
    image = args.image is not None
    size = args.size or (256 if image else 128)
    components = parse_counts(args.components or ("2000,8000,16000" if image else "20000"),
                              "--components")
    gradient = parse_counts(args.gradient_steps or ("100,300,1000,3000" if image
                                                    else "100,300,900,3000"),
                            "--gradient-steps")
    argv = ["front", *(["--image", args.image] if image else ["--scene", args.scene]),
            "--size", str(size), "--components", ",".join(map(str, components)),
            "--gradient-steps", ",".join(map(str, gradient)), "--seed", str(args.seed)]
    if image:
        from experiments.studies.front import run_image_front

        for k in components:
            check_fewer_components(k, size * size, f"a {size}x{size} image",
                                   "use fewer --components or a larger --size")
        argv += ["--iters", str(args.iters)]
        rows = run_image_front(args.image, size, components, args.iters, gradient,
                               seed=args.seed, progress=True)
        title = f"{name}, {size} px"
    else:
        from experiments.studies.front import run_scene_front
        from experiments.tasks.scene_task import SceneTask

        if len(components) != 1:
            raise ValueError(f"--components: a scene's front takes one count, got "
                             f"{args.components!r}")
        replays = tuple(r.strip() for r in args.replays.split(",") if r.strip())
        plan = FrontPlan(polish_steps=parse_counts(args.polish_steps, "--polish-steps"),
                         gradient_steps=gradient, replays=replays,
                         steps_per_frame=args.steps_per_frame, continual=bool(replays))
        base = SceneTask(scene=args.scene, format=args.format, components=components[0],
                         frames=args.frames, n_test=args.test_views, n_val=0, size=size,
                         seed=args.seed)
        check_fewer_components(components[0], args.frames * size**2,
                               f"at most {args.frames} frames x {size}x{size}",
                               "use fewer --components, a larger --size or more --frames")
        argv += ["--frames", str(args.frames), "--test-views", str(args.test_views),
                 "--polish-steps", ",".join(map(str, plan.polish_steps)),
                 "--replays", ",".join(replays), "--steps-per-frame", str(args.steps_per_frame)]
        rows = run_scene_front(base, plan, progress=True)
        title = (f"{name}, {size} px, {components[0]} components, {args.frames} frames")
    argv += ["--out", str(out)]
    files = write_front(rows, out, name, command="python -m experiments.run " + " ".join(argv),
                        title=title)
    return {"rows": rows, "files": [str(p) for p in files]}
