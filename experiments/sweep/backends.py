"""Where cells run: ``serial`` (in this process), ``local`` (a process pool on this
machine) or ``dask`` (an existing Dask distributed cluster).

Each backend takes the cells and yields finished records (see
:func:`experiments.sweep.cells.execute_cell`) in the order they finish; the caller
stores each one as it arrives. A task error is already a failed record; a worker that
dies (killed, out of memory) becomes a failed record here, so a sweep never stops for
one cell.

Local workers are started with the 'spawn' method and each held to one core *before*
JAX is imported in them: ``XLA_FLAGS=--xla_cpu_multi_thread_eigen=false
intra_op_parallelism_threads=1``, ``OMP_NUM_THREADS=1`` and friends, and (on Linux) CPU
affinity to a core of its own, worker i on the i-th allowed CPU. The affinity is what
actually holds XLA's CPU runtime to one thread in current JAX releases (the flags alone
left a worker using 1.7 cores here), so N workers use N cores instead of N x cores
threads fighting over them. JAX compilation dominates
small cells, so the local backend (a) hands each worker chunks of cells that share
array shapes (same settings apart from :data:`~experiments.sweep.cells.AFFINITY_FREE`), compiling each shape
once per worker, and (b) turns on JAX's persistent compilation cache in the workers
(``~/.cache/vbgs/jax``; set ``VBGS_JAX_CACHE`` to another folder, or to ``off``).
Records travel back to this process through a queue, one per finished cell.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import queue
import sys
import time
import traceback
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from experiments.sweep.cells import Cell, execute_cell, failed_record, shape_signature

BACKENDS = ("local", "serial", "dask")

SINGLE_THREAD_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "TF_NUM_INTEROP_THREADS": "1",
    "TF_NUM_INTRAOP_THREADS": "1",
}
SINGLE_THREAD_XLA = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
LOST_AFTER_S = 10.0  # how long to wait for the records of a chunk that returned


class BackendError(ValueError):
    """A backend that cannot start (missing extra, unreachable scheduler, bad option)."""


def compile_cache_dir() -> str | None:
    """Where workers keep JAX's persistent compilation cache (None: off)."""
    value = os.environ.get("VBGS_JAX_CACHE")
    if value is not None:
        return None if value.lower() in ("", "0", "off", "none") else value
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return str(Path(base) / "vbgs" / "jax")


_RESULTS = None  # in a local worker: the queue its records go back through


def _pin(slot, cpus: list[int]) -> None:
    """Pin this process to the next CPU of ``cpus`` (slot: a shared counter)."""
    if slot is None or not cpus or not hasattr(os, "sched_setaffinity"):
        return
    with slot.get_lock():
        index = slot.value
        slot.value += 1
    try:
        os.sched_setaffinity(0, {cpus[index % len(cpus)]})
    except OSError:  # a CPU that went away, a container refusing: run unpinned
        pass


def single_thread_worker(results=None, cache_dir: str | None = None, slot=None,
                         cpus: list[int] | None = None) -> None:
    """Pool initializer: one compute thread per worker process (thread-count variables
    and a CPU of its own), and the compilation cache. Runs before any task is
    unpickled, hence before JAX is imported here (XLA sizes its pools by the CPUs it
    may use)."""
    global _RESULTS
    _RESULTS = results
    _pin(slot, cpus or [])
    os.environ.update(SINGLE_THREAD_ENV)
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {SINGLE_THREAD_XLA}".strip()
    if cache_dir:
        os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", cache_dir)
        os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    if "jax" in sys.modules:  # too late for the flags to take effect; say so
        print("sweep worker: jax was imported before the thread limits were set",
              file=sys.stderr)


def _run_chunk(cells: list[tuple[str, dict]]) -> int:
    """In a local worker: run cells one after another, sending each record back."""
    for key, settings in cells:
        _RESULTS.put(execute_cell(key, settings))
    return len(cells)


def _crashed(cell: Cell, err: BaseException) -> dict:
    return failed_record(cell.key, cell.as_dict(), f"worker failed: {type(err).__name__}: {err}",
                         "".join(traceback.format_exception(err)))


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
    """A spawn process pool of ``workers`` processes running shape-affine chunks."""
    if not cells:
        return
    chunks = affinity_chunks(cells, workers)
    ctx = multiprocessing.get_context("spawn")
    results = ctx.Queue()
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    pool = ProcessPoolExecutor(max_workers=max(1, min(workers, len(chunks))), mp_context=ctx,
                               initializer=single_thread_worker,
                               initargs=(results, compile_cache_dir(), ctx.Value("i", 0), cpus))
    reported: set[str] = set()
    try:
        futures = {pool.submit(_run_chunk, [(c.key, c.as_dict()) for c in chunk]): chunk
                   for chunk in chunks}
        quiet_since = None
        while len(reported) < len(cells):
            try:
                record = results.get(timeout=0.5)
            except queue.Empty:
                all_done = all(f.done() for f in futures)
                quiet_since = (quiet_since or time.monotonic()) if all_done else None
                for future, chunk in futures.items():
                    broken = future.done() and future.exception() is not None
                    lost = quiet_since and time.monotonic() - quiet_since > LOST_AFTER_S
                    if broken or lost:
                        err = future.exception() or RuntimeError("the record never came back")
                        for cell in chunk:
                            if cell.key not in reported:
                                reported.add(cell.key)
                                yield _crashed(cell, err)
                continue
            if record["key"] not in reported:
                reported.add(record["key"])
                yield record
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


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
                yield _crashed(futures[future], err)
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
