"""Components spread over several devices, for scenes whose mixture does not fit one.

Every per-component array of a :class:`vbgs.inference.model.State` (prior, posterior and
statistics: means, scales, counts, ... all ``[k, ...]``) is split along its component
axis over a one-axis device mesh (``Mesh(devices, ("k",))`` with
``NamedSharding(mesh, P("k"))``); the frame origin and the batch of points are
replicated. The update functions need no change: they are jitted, and XLA's SPMD
partitioner splits the E-step along the components (each device scores the batch
against its own components; the log-sum-exp over components and the ELBO are
reduced across devices) and keeps every statistic and posterior on the device that
owns the component. Results equal the one-device update up to float32 summation
order (tested to 1e-5).

Several hosts: start every process with ``jax.distributed.initialize(...)`` (see the
README); ``jax.devices()`` then lists the devices of all hosts and :func:`mesh` spans
them, each host feeding the same batches.
"""

from __future__ import annotations

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from vbgs import CPU_SCHEDULER_FLAG
from vbgs.inference.model import Mixture, State

AXIS = "k"

# XLA:CPU runs a step's independent operations concurrently on one intra-op thread pool
# shared by all host devices of the process. A device waiting in an all-reduce holds a
# pool thread; when the other devices' work is queued behind it (a pool of as many
# threads as cores, fewer than the devices' concurrent work), the all-reduce never
# completes and XLA aborts after 40 s ("all-reduce rendezvous timed out"). Seen with 2
# host devices on this 2-core machine under load, and every time with one core
# (``taskset -c 0``) from 20k components. Scheduling each device's operations one after
# another (the concurrency-optimised scheduler off, as importing vbgs sets for every
# process: vbgs.CPU_SCHEDULER_FLAG) removes the wait on the pool.
HOST_DEVICE_XLA_FLAGS = (CPU_SCHEDULER_FLAG,)


def mesh(n_devices: int | None = None, devices=None) -> Mesh:
    """A one-axis mesh named ``"k"`` over the first ``n_devices`` devices (all by default)."""
    devices = list(jax.devices() if devices is None else devices)
    n = len(devices) if n_devices is None else int(n_devices)
    if not 1 <= n <= len(devices):
        raise ValueError(f"asked for {n} devices but {len(devices)} are available "
                         "(host CPUs: set XLA_FLAGS=--xla_force_host_platform_device_count=N)")
    return Mesh(np.asarray(devices[:n]), (AXIS,))


def host_device_flags(n_devices: int, existing: str = "") -> str:
    """``XLA_FLAGS`` for a process with ``n_devices`` host CPU devices: ``existing`` flags
    plus the device count and :data:`HOST_DEVICE_XLA_FLAGS` (must be set before JAX
    starts, so in a new process's environment)."""
    flags = [f for f in existing.split() if not f.startswith(
        "--xla_force_host_platform_device_count")]
    return " ".join([*flags, f"--xla_force_host_platform_device_count={int(n_devices)}",
                     *HOST_DEVICE_XLA_FLAGS])


def _shard_mixture(q: Mixture, split: NamedSharding, whole: NamedSharding) -> Mixture:
    parts = jax.tree_util.tree_map(lambda a: jax.device_put(a, split), q._replace(origin=None))
    return parts._replace(origin=jax.device_put(q.origin, whole))


def shard_state(state: State, on: Mesh) -> State:
    """``state`` with its per-component arrays split over ``on`` along the components.

    The number of components must be a multiple of the number of devices.
    """
    k, n = state.prior.n_components, on.devices.size
    if k % n:
        raise ValueError(f"{k} components do not split evenly over {n} devices: "
                         f"use a multiple of {n} components")
    split, whole = NamedSharding(on, P(AXIS)), NamedSharding(on, P())
    return state._replace(prior=_shard_mixture(state.prior, split, whole),
                          posterior=_shard_mixture(state.posterior, split, whole),
                          stats=jax.tree_util.tree_map(lambda a: jax.device_put(a, split),
                                                       state.stats))


def shard_prior(prior: Mixture, on: Mesh) -> Mixture:
    """A prior with its per-component arrays split over ``on`` (see :func:`shard_state`)."""
    k, n = prior.n_components, on.devices.size
    if k % n:
        raise ValueError(f"{k} components do not split evenly over {n} devices: "
                         f"use a multiple of {n} components")
    return _shard_mixture(prior, NamedSharding(on, P(AXIS)), NamedSharding(on, P()))
