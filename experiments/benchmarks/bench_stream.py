"""``bench stream``: seconds per streamed frame end to end, compilation apart, and a
profile of one frame.

End to end means what a learner pays per arriving frame: unprojecting the RGB-D frame
to points, padding on the host, the candidate search, the compiled E-/M-step and
waiting for the result (:class:`vbgs.inference.stepper.Stepper`). Building the stepper (prior
terms, candidate structure) is reported as ``setup_s``; the compilation inside it and
the whole time of frames whose call compiled as ``compile_s``; ``s_per_frame``
averages the frames that did not compile.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np
from experiments.progress import progress as progress_bar

from vbgs.compilation import CompileTimer
from vbgs.inference import candidates, grid, model, stepper

PROFILE_REPEATS = 3
# Frames of more pixels than this are a sensor's (640 x 480): their rows stream
# LARGE_FRAMES frames of the first scene at the largest component count only (the ray
# caster renders a 640 x 480 frame in seconds on 2 cores), every point and then within
# LARGE_BUDGET points a frame (vbgs.mapping.budget).
LARGE_PIXELS = 4 * 128 * 128
LARGE_FRAMES = 10
LARGE_BUDGET = 20000


def table_name() -> str:
    """The results file on this backend: ``bench_stream`` on the CPU (the committed
    table), ``bench_stream_<backend>`` elsewhere, so a GPU run never overwrites the CPU
    figures (the table's machine line names the device, :func:`experiments.benchmarks.bench.machine`)."""
    backend = jax.default_backend()
    return "bench_stream" if backend == "cpu" else f"bench_stream_{backend}"


def _prior(scene, k: int, seed: int = 0):
    from experiments.tasks.protocol import frame_points

    xyz, rgb = (np.concatenate(a) for a in zip(*map(frame_points, scene.train), strict=True))
    return model.init(xyz, rgb, k, key=jax.random.key(seed), scheme="data", bounds=scene.bounds)


def stream_row(scene, prior, estep: str, *, frames: int, search: str = "auto",
               assign: str = "prior", budget_points: int = 0) -> dict:
    """Stream ``frames`` frames through a fresh stepper; timings of one row.
    ``budget_points``: each frame thinned to at most this many points, weighted
    (:mod:`vbgs.mapping.budget`; 0: every point), the thinning timed with the frame."""
    from experiments.tasks.protocol import peak_memory_mb
    from vbgs.mapping import budget
    from vbgs.render.camera import unproject

    timer = CompileTimer()
    with timer:
        t0 = time.perf_counter()
        step = stepper.Stepper(prior, assign=assign, estep=estep, search=search)
        jax.block_until_ready(step.fixed)
        setup = time.perf_counter() - t0
    setup -= timer.seconds  # the prior terms' compilation counts as compilation
    state, compile_s, steady, counts = model.start(prior), timer.seconds, [], []
    key = jax.random.key(0)
    for frame in scene.train[:frames]:
        key, sub = jax.random.split(key)
        timer = CompileTimer()
        with timer:
            t0 = time.perf_counter()
            depth, weight = budget.thin(frame.depth, budget_points, key=sub)
            xyz, rgb = unproject(frame.camera, frame.rgb, depth)
            state, _ = step(state, xyz, rgb, weight=weight)
            jax.block_until_ready(state.stats.count)
            seconds = time.perf_counter() - t0
        counts.append(len(xyz))
        if timer.seconds > 0:
            compile_s += seconds
        else:
            steady.append(seconds)
    return {"assign": assign, "estep": estep, "search": step.search if estep == "sparse" else "-",
            "budget": budget_points, "frames": len(counts), "points_per_frame": int(np.mean(counts)),
            "padded": step.size, "setup_s": setup, "compile_s": compile_s,
            "s_per_frame": float(np.mean(steady)) if steady else float("nan"),
            "total_s": setup + compile_s + float(np.sum(steady)),
            "peak_memory_mb": peak_memory_mb(), "devices": len(jax.devices())}


def _timed(fn, *args):
    jax.block_until_ready(fn(*args))
    t0 = time.perf_counter()
    for _ in range(PROFILE_REPEATS):
        jax.block_until_ready(fn(*args))
    return (time.perf_counter() - t0) / PROFILE_REPEATS


def profile_frame(scene, prior, *, search: str = "auto") -> list[dict]:
    """Seconds of each stage of one streamed frame (sparse E-step, prior assignment),
    each stage compiled and timed on its own (warm, mean of a few runs)."""
    from experiments.tasks.protocol import frame_points

    frame = scene.train[len(scene.train) // 2]
    rows = []
    t0 = time.perf_counter()
    for _ in range(PROFILE_REPEATS):
        xyz, rgb = frame_points(frame)
    rows.append(("unprojection (host)", (time.perf_counter() - t0) / PROFILE_REPEATS))
    t0 = time.perf_counter()
    step = stepper.Stepper(prior, estep="sparse", search=search)
    jax.block_until_ready(step.fixed)
    rows.append((f"stepper setup, once per stream ({step.search})", time.perf_counter() - t0))
    size = step.padded_size(len(xyz))
    t0 = time.perf_counter()
    for _ in range(PROFILE_REPEATS):
        x, c, w = model.padded_batch(xyz, rgb, prior.origin, size, np.float32)
    rows.append(("validate + pad (host)", (time.perf_counter() - t0) / PROFILE_REPEATS))
    rows.append(("copy batch host -> device", _timed(jax.device_put, (x, c, w))))
    xd, cd, wd = jax.device_put((x, c, w))
    if step.search == "grid":
        search_fn = jax.jit(grid.search, static_argnums=4)
        args = (step.fixed.lists, prior.space.mean, xd, wd, step.spec)
        rows.append(("candidate search (device grid)", _timed(search_fn, *args)))
        cand = search_fn(*args)
    else:
        tree = candidates.means_tree(prior.space.mean)
        t0 = time.perf_counter()
        for _ in range(PROFILE_REPEATS):
            cand = candidates.query(tree, x, step.n_candidates)
        rows.append(("candidate search (host KD-tree)", (time.perf_counter() - t0)
                     / PROFILE_REPEATS))
        cand = jnp.asarray(cand)
    chunk = step._chunk(size)
    e_fn = jax.jit(lambda r, x, c, w, cand: model.e_step_with(r, x, c, w, step.colour_noise,
                                                              chunk, cand))
    rows.append(("E-step (sparse, centred form)", _timed(e_fn, step.fixed.reference, xd, cd, wd,
                                                        cand)))
    stats, _ = e_fn(step.fixed.reference, xd, cd, wd, cand)
    rows.append(("M-step", _timed(jax.jit(model.m_step), prior, stats)))
    state = model.start(prior)
    stepper._step.clear_cache()  # compile afresh (a load, where the persistent cache has it)
    timer = CompileTimer()
    with timer:
        step(state, xyz, rgb)
    rows.append(("compile the whole step (once per padded size)", timer.seconds))
    rows.append(("whole step, warm (search + E + M + copies)",
                 _timed(lambda: step(state, xyz, rgb)[0].stats.count)))
    out = step(state, xyz, rgb)[0].stats.count
    rows.append(("copy counts device -> host (if asked)", _timed(np.asarray, out)))
    return [{"stage": name, "seconds": s} for name, s in rows]


def bench_stream(components=(20000, 50000, 100000), scenes=("object", "room"),
                 esteps=("dense", "sparse"), *, frames: int = 60, dense_frames: int = 8,
                 sizes=(128,), search: str = "auto", dense_max: int = 50000,
                 progress: bool = False) -> list[dict]:
    """Rows of :func:`stream_row` for each size, scene, component count and E-step. The
    dense E-step streams only ``dense_frames`` frames and only up to ``dense_max``
    components (it costs ``n x k`` per frame). A size of more than :data:`LARGE_PIXELS`
    pixels (``"640x480"``, :func:`vbgs.data.scene.parse_size`) gives the rows of
    :func:`large_cells` instead."""
    from vbgs.data.formats import load_scene
    from vbgs.data.scene import size_pixels, size_text

    cells = []
    for size in sizes:
        if size_pixels(size) > LARGE_PIXELS:
            cells += large_cells(size, components, scenes, frames)
        else:
            cells += [(size, s, k, e, 0, frames if e == "sparse" else dense_frames)
                      for s in scenes for k in components for e in esteps
                      if e == "sparse" or k <= dense_max]
    rows, loaded, priors = [], {}, {}
    for size, scene_name, k, estep, points, n in progress_bar(
            cells, desc="bench stream", unit="cell", enabled=progress):
        n_train = min(frames, LARGE_FRAMES) if size_pixels(size) > LARGE_PIXELS else frames
        if (size, scene_name) not in loaded:
            loaded = {(size, scene_name): load_scene(scene_name, size=size, n_train=n_train,
                                                     n_test=1, seed=0)}
        scene = loaded[(size, scene_name)]
        if (size, scene_name, k) not in priors:
            priors = {(size, scene_name, k): _prior(scene, k)}
        row = stream_row(scene, priors[(size, scene_name, k)], estep, frames=n, search=search,
                         budget_points=points)
        rows.append({"scene": scene_name, "size": size_text(size), "components": k, **row})
    return rows


def large_cells(size, components, scenes, frames: int) -> list[tuple]:
    """The cells of a sensor-sized frame: the last scene (the room by default: every
    pixel has depth), the largest component count, the sparse E-step, at most
    :data:`LARGE_FRAMES` frames, every point and then :data:`LARGE_BUDGET` points."""
    n = min(frames, LARGE_FRAMES)
    return [(size, scenes[-1], max(components), "sparse", points, n)
            for points in (0, LARGE_BUDGET)]


def speedups(rows: list[dict]) -> list[dict]:
    """Sparse over dense seconds per frame, per scene and component count."""
    out = []
    for r in rows:
        if r["estep"] != "sparse":
            continue
        dense = [d for d in rows if d["estep"] == "dense" and d["scene"] == r["scene"]
                 and d["components"] == r["components"]]
        if dense:
            out.append({"scene": r["scene"], "components": r["components"],
                        "sparse_over_dense": dense[0]["s_per_frame"] / r["s_per_frame"]})
    return out


def sharded_row(n_devices: int, k: int, scene_name: str, *, frames: int, size: int,
                estep: str) -> dict:
    """:func:`stream_row` with the components split over ``n_devices`` devices."""
    from vbgs.data.formats import load_scene
    from vbgs.inference import sharding

    scene = load_scene(scene_name, size=size, n_train=frames, n_test=1, seed=0)
    mesh = sharding.mesh(n_devices)
    prior = sharding.shard_prior(_prior(scene, k), mesh)
    row = stream_row(scene, prior, estep, frames=frames)
    return {"scene": scene_name, "size": size, "components": k, **row,
            "devices": n_devices}


DEVICE_NOTE = ("Rows by device count: the components are split over N devices (one process "
               "each). On a CPU these are N host devices forced onto the machine's own cores "
               "(XLA_FLAGS=--xla_force_host_platform_device_count=N): they share the same "
               "cores, so more devices cannot be faster here; the rows show that the sharded "
               "stream runs and what its collectives cost, not a multi-device speed-up.")


def device_rows(counts, k: int, scene_name: str, *, frames: int, size: int,
                estep: str = "sparse") -> list[dict]:
    """One :func:`sharded_row` per device count, each in a fresh process. On a CPU the
    process gets that many host devices (:func:`vbgs.inference.sharding.host_device_flags`, which
    also keeps XLA:CPU's all-reduce from starving on a machine with fewer cores than
    devices); on an accelerator the process's own devices are used."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    from vbgs.inference import sharding

    root = str(Path(__file__).resolve().parents[1])  # this checkout's packages first
    uneven = [n for n in counts if n < 1 or k % n]
    if uneven:
        raise ValueError(f"{k} components do not split evenly over {uneven} devices: use a "
                         f"component count that every --devices value divides")
    rows = []
    for n in counts:
        env = {**os.environ,
               "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
        if jax.default_backend() == "cpu":
            env["XLA_FLAGS"] = sharding.host_device_flags(n, env.get("XLA_FLAGS", ""))
        code = ("import json; from experiments.benchmarks.bench_stream import sharded_row; "
                "from vbgs.compilation import enable_persistent_cache; "
                "enable_persistent_cache(); "  # as every CLI command (opt-out respected)
                f"print(json.dumps(sharded_row({n}, {k}, {scene_name!r}, frames={frames}, "
                f"size={size}, estep={estep!r})))")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             env=env, check=False)
        if out.returncode:
            raise RuntimeError(f"bench stream on {n} devices failed: {out.stderr[-2000:]}")
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    return rows
