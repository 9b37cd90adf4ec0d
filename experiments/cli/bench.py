"""``bench``: benchmarks (image, estep, stream, raster, depth); figures printed and written
as CSV and markdown."""

from __future__ import annotations

from experiments.cli.options import add_json
from experiments.cli.output import size_arg


def add(sub):
    p = sub.add_parser("bench", help="benchmarks; figures are printed and written as CSV/markdown")
    p.add_argument("target", choices=["image", "estep", "stream", "raster", "depth"],
                   help="image: CAVI per iteration; estep: dense vs sparse per frame; "
                        "stream: seconds per streamed frame end to end, with a profile; "
                        "raster: 3-D rasterizer; depth: ONNX adapter throughput")
    p.add_argument("--sizes", type=size_arg, nargs="+", default=None,
                   help="image sizes (image: 64 128, raster: 128 256, estep: 128)")
    p.add_argument("--components", type=int, nargs="+", default=None,
                   help="component counts (image: 500..8000, estep: 20000 50000)")
    p.add_argument("--iters", type=int, default=3, help="timed CAVI iterations per cell")
    p.add_argument("--frames", type=int, default=60, help="stream: frames streamed per row")
    p.add_argument("--scenes", nargs="+", default=["object", "room"], help="stream: scenes")
    p.add_argument("--search", choices=["auto", "grid", "kdtree"], default="auto",
                   help="stream: sparse candidate search (auto: KD-tree on CPU, grid elsewhere)")
    p.add_argument("--devices", type=int, nargs="+", default=None,
                   help="stream: rows with the components sharded over N devices (host CPUs: "
                        "one process each with N forced host devices), first component count")
    p.add_argument("--impl", choices=["auto", "xla", "pallas"], default="auto",
                   help="raster: compositing code (auto: pallas on a GPU, xla otherwise; "
                        "pallas off a GPU runs in interpret mode, slow)")
    p.add_argument("--out", default="runs/bench", help="folder for the CSV and markdown table "
                   "(default runs/bench, ignored by git)")
    add_json(p)


def run(args) -> dict:
    from experiments.benchmarks import bench

    progress = True
    defaults = {"image": ([64, 128], [500, 1000, 2000, 4000, 8000]),
                "estep": ([128], [20000, 50000]), "raster": ([128, 256], [10_000, 50_000]),
                "stream": ([128], [20000, 50000, 100000]), "depth": ([256], None)}[args.target]
    sizes, components = args.sizes or defaults[0], args.components or defaults[1]
    if args.target == "image":
        rows = bench.bench_image(sizes, components, iters=args.iters, progress=progress)
    elif args.target == "estep":
        rows = bench.bench_estep(components, size=sizes[0], progress=progress)
    elif args.target == "stream":
        from experiments.benchmarks import bench_stream
        from vbgs.data.scene import size_text

        rows = bench_stream.bench_stream(tuple(args.components or (20000, 50000, 100000)),
                                         tuple(args.scenes), frames=args.frames,
                                         sizes=tuple(sizes), search=args.search,
                                         progress=progress)
        devices = []
        if args.devices:
            devices = bench_stream.device_rows(args.devices, (args.components or [20000])[0],
                                               args.scenes[0], frames=args.frames,
                                               size=(args.sizes or [128])[0])
        profile = stream_profile(args.scenes[0], (args.components or [20000])[0],
                                  (args.sizes or [128])[0], args.search)
        command = " ".join(["python -m experiments.run bench stream --components",
                            *map(str, components), "--scenes", *args.scenes, "--frames",
                            str(args.frames), "--sizes", *map(size_text, sizes),
                            "--search", args.search]
                           + (["--devices", *map(str, args.devices)] if args.devices else []))
        name = bench_stream.table_name()
        paths = bench.write_table(rows, args.out, name, command=command)
        paths += bench.write_table(profile, args.out, f"{name}_profile", command=command)
        if devices:
            paths += bench.write_table(devices, args.out, f"{name}_devices",
                                       command=command, note=bench_stream.DEVICE_NOTE)
        if not args.json:
            from tabulate import tabulate

            print(f"profile of one frame ({args.scenes[0]}, sparse E-step):")
            print(tabulate(profile, headers="keys", floatfmt=".4g", tablefmt="github"))
            print(tabulate(bench_stream.speedups(rows), headers="keys", floatfmt=".3g",
                           tablefmt="github"))
            if devices:
                print("by device count (host devices share this machine's cores):")
                print(tabulate(devices, headers="keys", floatfmt=".4g", tablefmt="github"))
        return {"rows": rows, "speedups": bench_stream.speedups(rows), "profile": profile,
                "devices": devices, "files": [str(p) for p in paths]}
    elif args.target == "raster":
        from experiments.benchmarks.bench_raster import bench_rasterizer, table_name

        rows = bench_rasterizer(sizes=tuple(sizes), counts=tuple(components), impl=args.impl)
    else:
        from depth.bench import bench_adapter

        rows = [bench_adapter(size=sizes[0])]
    command = " ".join(["python -m experiments.run bench", args.target,
                        "--sizes", *map(str, sizes)]
                       + (["--components", *map(str, components)] if components else [])
                       + (["--iters", str(args.iters)] if args.target == "image" else [])
                       + (["--impl", args.impl] if args.target == "raster" else [])
                       + ["--out", str(args.out)])
    name = table_name(args.impl) if args.target == "raster" else f"bench_{args.target}"
    paths = bench.write_table(rows, args.out, name, command=command)
    return {"rows": rows, "files": [str(p) for p in paths]}


def stream_profile(scene_name: str, k: int, size: int, search: str) -> list[dict]:
    from experiments.benchmarks.bench_stream import _prior, profile_frame
    from vbgs.data.formats import load_scene

    scene = load_scene(scene_name, size=size, n_train=20, n_test=1, seed=0)
    return [{"scene": scene_name, "components": k, **row}
            for row in profile_frame(scene, _prior(scene, k), search=search)]
