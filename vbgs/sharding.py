"""Components spread over several devices, for scenes whose mixture does not fit one.

Every per-component array of a :class:`vbgs.model.State` (prior, posterior and
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

from vbgs.model import Mixture, State

AXIS = "k"


def mesh(n_devices: int | None = None, devices=None) -> Mesh:
    """A one-axis mesh named ``"k"`` over the first ``n_devices`` devices (all by default)."""
    devices = list(jax.devices() if devices is None else devices)
    n = len(devices) if n_devices is None else int(n_devices)
    if not 1 <= n <= len(devices):
        raise ValueError(f"asked for {n} devices but {len(devices)} are available "
                         "(host CPUs: set XLA_FLAGS=--xla_force_host_platform_device_count=N)")
    return Mesh(np.asarray(devices[:n]), (AXIS,))


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
