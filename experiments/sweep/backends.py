"""Where cells run: ``serial`` (in this process), ``local`` (worker processes on this
machine) or ``dask`` (an existing Dask distributed cluster).

Each backend takes the cells and yields finished records (see
:func:`experiments.sweep.cells.execute_cell`) in the order they finish; the caller
stores each one as it arrives. A task error is already a failed record; a worker that
dies (killed, out of memory) becomes a failed record here, so a sweep never stops for
one cell.

Local workers are 'spawn'ed processes, each held to one core *before* JAX is imported
in it: ``XLA_FLAGS=--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1``,
``OMP_NUM_THREADS=1`` and friends, and (on Linux) CPU affinity, worker i on the i-th
allowed CPU. The affinity is what actually holds XLA's CPU runtime to one core in
current JAX releases (with the flags alone a worker used 1.7 cores here), so N workers
use N cores instead of N x cores threads fighting over them.

JAX compilation dominates small cells, so workers take *chunks* of cells that share
array shapes (same settings apart from ``cells.AFFINITY_FREE``), compiling each shape
once per worker, and share JAX's persistent compilation cache, the CLI's
(:func:`vbgs.compilation.cache_dir`: ``~/.cache/vbgs/jax``; ``VBGS_COMPILE_CACHE`` moves
it, ``VBGS_NO_COMPILE_CACHE=1`` turns it off). Records come back through a
queue, one per finished cell. Stopping the sweep (Ctrl-C, an error) terminates the
workers; a worker whose sweep was killed outright stops before its next cell.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import queue
import sys
import threading
import traceback
from collections.abc import Iterable, Iterator

from experiments.sweep.cells import Cell, execute_cell, failed_record, shape_signature
from vbgs.compilation import cache_dir

BACKENDS = ("local", "serial", "dask")

SINGLE_THREAD_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "TF_NUM_INTEROP_THREADS": "1",
    "TF_NUM_INTRAOP_THREADS": "1",
}
SINGLE_THREAD_XLA = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


class BackendError(ValueError):
    """A backend that cannot start (missing extra, unreachable scheduler, bad option)."""


def compile_cache_dir() -> str | None:
    """Where workers keep JAX's persistent compilation cache (None: off): the CLI's."""
    folder = cache_dir()
    return None if folder is None else str(folder)


def single_thread_worker(cache_dir: str | None = None, cpu: int | None = None) -> None:
    """Hold this (fresh) process to one core and point JAX at the compilation cache.
    Must run before JAX is imported here: XLA sizes its thread pools at start-up."""
    if cpu is not None and hasattr(os, "sched_setaffinity"):
        try:
            os.sched_setaffinity(0, {cpu})
        except OSError:  # a CPU that went away, a container refusing: run unpinned
            pass
    os.environ.update(SINGLE_THREAD_ENV)
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {SINGLE_THREAD_XLA}".strip()
    if cache_dir:
        os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", cache_dir)
        os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    if "jax" in sys.modules:  # too late for the limits to take effect; say so
        print("sweep worker: jax was imported before the thread limits were set",
              file=sys.stderr)


def _worker(tasks, results, cache_dir: str | None, cpu: int | None, parent: int) -> None:
    """A local worker: take chunks until the ``None`` sentinel; report each cell's start
    and record. Stops before a cell when the sweep process is gone."""
    single_thread_worker(cache_dir, cpu)
    from tqdm import tqdm

    tqdm.set_lock(threading.RLock())  # not tqdm's default process-shared lock, which a
    # worker stopped by Ctrl-C would leave behind as a "leaked semaphore"
    try:
        while (chunk := tasks.get()) is not None:
            for key, settings in chunk:
                if os.getppid() != parent:
                    return
                results.put(("start", os.getpid(), key))
                results.put(("done", os.getpid(), execute_cell(key, settings)))
    except KeyboardInterrupt:  # Ctrl-C reaches the workers too; the sweep reports it
        return


def _crashed(cell: Cell, why: str, err: BaseException | None = None) -> dict:
    tb = "".join(traceback.format_exception(err)) if err is not None else ""
    return failed_record(cell.key, cell.as_dict(), why, tb)


def affinity_chunks(cells: list[Cell], workers: int) -> list[list[Cell]]:
    """Cells grouped by shape-relevant settings, split so every worker gets work
    (chunks of at most ceil(n / (2 workers)) cells), largest chunks first."""
    groups: dict[tuple, list[Cell]] = {}
    for cell in cells:
        groups.setdefault(shape_signature(cell.as_dict()), []).append(cell)
    size = max(1, math.ceil(len(cells) / (2 * workers)))
    chunks = [g[i:i + size] for g in groups.values() for i in range(0, len(g), size)]
    return sorted(chunks, key=len, reverse=True)


def run_serial(cells: Iterable[Cell]) -> Iterator[dict]:
    for cell in cells:
        yield execute_cell(cell.key, cell.as_dict())


def run_local(cells: list[Cell], workers: int) -> Iterator[dict]:
    """``workers`` spawned processes (at most one per chunk) running shape-affine chunks."""
    if not cells:
        return
    chunks = affinity_chunks(cells, workers)
    n = max(1, min(workers, len(chunks)))
    ctx = multiprocessing.get_context("spawn")
    tasks, results = ctx.Queue(), ctx.Queue()
    for chunk in chunks:
        tasks.put([(c.key, c.as_dict()) for c in chunk])
    for _ in range(n):
        tasks.put(None)
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    procs = [ctx.Process(target=_worker, name=f"sweep-worker-{i}", daemon=True,
                         args=(tasks, results, compile_cache_dir(),
                               cpus[i % len(cpus)] if cpus else None, os.getpid()))
             for i in range(n)]
    for p in procs:
        p.start()
    by_key = {c.key: c for c in cells}
    running: dict[int, str] = {}  # worker pid -> key of the cell it is running
    reported: set[str] = set()
    try:
        while len(reported) < len(cells):
            try:
                kind, pid, payload = results.get(timeout=0.5)
            except queue.Empty:
                for p in procs:  # a worker that died takes its cell in flight with it
                    if p.exitcode not in (0, None) and p.pid in running:
                        key = running.pop(p.pid)
                        reported.add(key)
                        yield _crashed(by_key[key], f"worker process {p.pid} died (exit code "
                                       f"{p.exitcode}): killed, or out of memory?")
                if not any(p.is_alive() for p in procs):  # the rest of its chunk: not run
                    for key in by_key.keys() - reported:
                        reported.add(key)
                        yield _crashed(by_key[key], "not run: its worker process died")
                continue
            if kind == "start":
                running[pid] = payload
            elif payload["key"] not in reported:
                running.pop(pid, None)
                reported.add(payload["key"])
                yield payload
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(timeout=5)
        for q in (tasks, results):
            q.close()
            q.cancel_join_thread()


def dask_client(scheduler: str | None):
    """A client of the Dask cluster at ``scheduler``, or a :class:`BackendError`."""
    if not scheduler:
        raise BackendError("--backend dask needs --scheduler ADDRESS of a running Dask "
                           "scheduler, e.g. tcp://10.0.0.5:8786")
    try:
        from dask.distributed import Client
    except ImportError as err:
        raise BackendError("the dask backend needs Dask distributed: "
                           "pip install 'vbgs[dask]' (or 'dask[distributed]')") from err
    try:
        return Client(scheduler, timeout="20s")
    except OSError as err:
        raise BackendError(f"could not connect to the Dask scheduler at {scheduler!r}: "
                           f"{err}") from None


def run_dask(cells: list[Cell], client) -> Iterator[dict]:
    """Submit every cell to the cluster behind ``client``; yield as they finish.

    Workers import ``experiments`` themselves, so the package must be installed where
    they run; they return records (images included) to this process, which stores
    them, so no shared file system is needed. Start workers with
    ``OMP_NUM_THREADS=1`` and ``--nthreads 1`` per core for the best throughput.
    """
    from dask.distributed import as_completed

    try:
        futures = {client.submit(execute_cell, c.key, c.as_dict(), pure=False): c
                   for c in cells}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as err:  # the worker died or could not run the function
                yield _crashed(futures[future], f"{type(err).__name__}: {err}", err)
            future.release()
    finally:
        client.close()


def run_cells(cells: list[Cell], backend: str, *, workers: int | None = None,
              scheduler: str | None = None) -> Iterator[dict]:
    """Records of ``cells`` run on ``backend``, in the order they finish."""
    if backend == "serial":
        return run_serial(cells)
    if backend == "local":
        return run_local(cells, workers or os.cpu_count() or 1)
    if backend == "dask":
        return run_dask(cells, dask_client(scheduler))
    raise BackendError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
