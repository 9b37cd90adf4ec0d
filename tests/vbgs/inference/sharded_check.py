"""Run by test_sharding.py in a subprocess with 4 host CPU devices: prints the largest
differences between the sharded and the one-device updates as JSON."""

import json
import sys

import jax
import numpy as np

from vbgs.data.synthetic import object_scene
from vbgs.inference import model, sharding, stepper
from vbgs.render.camera import unproject


def main() -> None:
    assert len(jax.devices()) == 4, jax.devices()
    scene = object_scene(size=24, n_train=3, n_test=1, seed=0)
    # float64 (JAX_ENABLE_X64 in the test's environment): the comparison is of the
    # sharded algorithm, not of float32 summation order across devices
    pts = [tuple(a.astype(np.float64) for a in unproject(f.camera, f.rgb, f.depth))
           for f in scene.train]
    xyz, rgb = (np.concatenate(a) for a in zip(*pts, strict=True))
    prior = model.init(xyz, rgb, 400, key=jax.random.key(0), scheme="data", bounds=scene.bounds)
    out = {}
    # posterior assignment amplifies float32 rounding from batch to batch (sharded or
    # not), so each variant makes one update from the same learned state
    learned, _ = model.update(model.start(prior), *pts[0], assign="posterior")
    for assign, estep in (("prior", "dense"), ("posterior", "dense"), ("prior", "sparse")):
        states = {}
        for n_dev in (1, 4):
            mesh = sharding.mesh(n_dev)
            p = sharding.shard_prior(prior, mesh)
            step = stepper.Stepper(p, assign=assign, estep=estep, search="grid")
            if assign == "prior":
                state, batches = model.start(p), pts
            else:
                state, batches = learned, pts[1:2]
            state = sharding.shard_state(state, mesh)
            for x, c in batches:
                state, info = step(state, x, c)
            states[n_dev] = (state, info)
        (one, i1), (four, i4) = states[1], states[4]
        n_shards = len(four.posterior.space.mean.sharding.device_set)

        def rel(a, b):
            a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
            return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-30))

        out[f"{assign}-{estep}"] = {
            "devices_holding_means": n_shards,
            "mean": rel(four.posterior.space.mean, one.posterior.space.mean),
            "scale": rel(four.posterior.space.scale, one.posterior.space.scale),
            "count": rel(four.stats.count, one.stats.count),
            "colour": rel(four.posterior.colour.mean, one.posterior.colour.mean),
            "elbo": rel(i4.elbo, i1.elbo),
        }
    try:
        sharding.shard_prior(model.init(xyz, rgb, 402, key=jax.random.key(0)), sharding.mesh(4))
        out["uneven_refused"] = False
    except ValueError as err:
        out["uneven_refused"] = "multiple of 4" in str(err)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
