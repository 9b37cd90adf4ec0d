"""Variational Bayes Gaussian Splatting in JAX.

Importing the package turns off XLA:CPU's concurrency-optimised scheduler for this
process (:func:`schedule_cpu_ops_in_sequence`) unless ``XLA_FLAGS`` already sets it. That
scheduler runs a computation's independent operations concurrently on the one intra-op
thread pool; when they outnumber the pool's threads (the cores), an operation can wait
on work queued behind it, and the computation never finishes. Seen here on a 2-core CPU:
a posterior-assignment stream (object, 128 px, 20k components) hung in one run of four,
at a different frame each time, and none of four with the flag; sharded updates over
host devices timed out in their all-reduce (:mod:`vbgs.inference.sharding`). The flag is read when
JAX starts its CPU backend, so it takes effect when ``vbgs`` is imported before any JAX
computation has run.
"""

import os

CPU_SCHEDULER_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler=false"


def schedule_cpu_ops_in_sequence(environ=os.environ) -> None:
    """Add :data:`CPU_SCHEDULER_FLAG` to ``environ["XLA_FLAGS"]`` unless the scheduler is
    already set there (either way)."""
    flags = environ.get("XLA_FLAGS", "")
    if "xla_cpu_enable_concurrency_optimized_scheduler" not in flags:
        environ["XLA_FLAGS"] = f"{flags} {CPU_SCHEDULER_FLAG}".strip()


schedule_cpu_ops_in_sequence()
