"""``fit-image``: fit one photo (batch CAVI or a patch stream) and score it."""

from __future__ import annotations

from experiments.cli.options import add_json, add_seed
from experiments.cli.output import check_fewer_components, check_fits_memory, check_output_file
from experiments.tasks.settings import ASSIGN, INIT, METHOD, ORDER, STREAM, add_choice


def add(sub):
    p = sub.add_parser("fit-image", help="fit one photo with VBGS and report PSNR/SSIM")
    p.add_argument("--image", default="astronaut", help="bundled photo name or image file path")
    p.add_argument("--size", type=int, default=64, help="resize to SIZE x SIZE (0: keep)")
    p.add_argument("--components", type=int, default=2000)
    p.add_argument("--iters", type=int, default=10, help="CAVI iterations (batch fits)")
    add_choice(p, "--init", INIT)
    add_seed(p)
    add_choice(p, "--stream", STREAM)
    add_choice(p, "--order", ORDER)
    add_choice(p, "--assign", ASSIGN)
    p.add_argument("--patch", type=int, default=8, help="patch side for --stream patches")
    p.add_argument("--reassign", choices=["on", "off", "auto"], default="auto",
                   help="re-seed unused components (auto: on for batch fits, off for streams)")
    add_choice(p, "--method", METHOD)
    p.add_argument("--steps", type=int, default=2000, help="optimiser steps (gradient)")
    p.add_argument("--save", metavar="PNG", help="write target, render and error side by side")
    add_json(p)


def run(args) -> dict:
    from experiments.tasks.image_task import ImageTask, run_image, save_comparison, task_image
    from vbgs.compilation import cache_root

    reassign = {"on": True, "off": False, "auto": args.stream == "none"}[args.reassign]
    task = ImageTask(image=args.image, size=args.size or None, components=args.components,
                     iters=args.iters, init=args.init, seed=args.seed, stream=args.stream,
                     order=args.order, assign=args.assign, patch=args.patch, reassign=reassign,
                     method=args.method, steps=args.steps)
    check_output_file(args.save, "--save", ".png")  # output paths and sizes before the fit
    if args.size:
        check_fits_memory(args.size, 1)
    root = cache_root()  # bundled photos kept resized: no skimage.transform, no SciPy
    image = task_image(task, cache=root and root / "images")  # once: checked, then fitted
    h, w, _ = image.shape
    check_fewer_components(args.components, h * w, f"{w}x{h} image",
                           "use fewer --components or a larger --size")
    result = run_image(task, progress=True, image=image)
    images = result.pop("images")
    if args.save:
        save_comparison(args.save, images["target"], images["render"],
                        f"{args.image}: {result['psnr']:.2f} dB, {args.components} components")
    return result
