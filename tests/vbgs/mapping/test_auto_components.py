"""components="auto": the count chosen from the data, slots grown in buckets."""

import sys

import jax
import numpy as np
import pytest

from vbgs import mapping
from vbgs.components import parse_components
from vbgs.data.formats import load_scene
from vbgs.inference import capacity, grow, stepper

MAPPER = sys.modules["vbgs.mapping.mapper"]  # the module (vbgs.mapping.mapper is a function)


@pytest.fixture(scope="module")
def scene():
    return load_scene("object", size=32, n_train=8, n_test=2, seed=0)


def test_components_setting_takes_k_auto_and_auto_max_and_refuses_the_rest():
    assert parse_components(500) == (False, 500)
    assert parse_components("auto") == (True, 131072)
    assert parse_components("auto:3000") == (True, 3000)
    for bad, words in (("auto:0", "auto:MAX"), ("abc", "'auto'"), (0, "positive integer"),
                       ("5000", "positive integer"), (True, "positive integer")):
        with pytest.raises(ValueError, match=words):
            parse_components(bad)
    with pytest.raises(ValueError, match="auto:MAX"):
        mapping.Config(components="auto:-3")


def test_buckets_double_up_to_the_ceiling():
    assert [capacity.bucket(n, 64, 1000) for n in (1, 64, 65, 200, 513, 5000)] == \
        [64, 64, 128, 256, 1000, 1000]


@pytest.mark.slow
def test_capacity_grows_in_buckets_without_a_compilation_per_frame(scene, monkeypatch):
    monkeypatch.setattr(MAPPER, "AUTO_BUCKET", 64)  # small buckets: several per stream
    config = mapping.Config(components="auto")
    stepper._step.clear_cache()  # count from zero: other tests compiled other shapes
    state = mapping.init(config, key=jax.random.key(0))
    capacities, active = [], []
    for frame in scene.train:
        state, _ = mapping.update(state, frame, config)
        capacities.append(state.mixture.prior.n_components)
        active.append(int(grow.is_active(state.mixture.prior).sum()))
    # measured (under the Bayes-factor splits): capacities 256, 256, 512 x6; 152
    # active after the first frame, 431 at the end (without splits the same capacities
    # and 399; the per-frame colour gain before split to 2048 slots and 1373)
    assert capacities == sorted(capacities) and len(set(capacities)) >= 2
    assert all(c in (64, 128, 256, 512, 1024, 2048) for c in capacities)
    assert 410 < active[-1] <= capacities[-1] and not state.capped
    # one compiled step per capacity (and point bucket), not one per frame
    assert stepper._step._cache_size() <= len(set(capacities)) + 1 < len(scene.train)


@pytest.mark.slow
def test_auto_reaches_its_ceiling_says_so_and_keeps_to_it(scene):
    config = mapping.Config(components="auto:200")
    state = mapping.init(config, key=jax.random.key(0))
    for frame in scene.train[:3]:  # measured: 100, 200, 200 active; capped on frame 2
        state, _ = mapping.update(state, frame, config)
    assert state.capped and state.mixture.prior.n_components == 200
    assert grow.is_active(state.mixture.prior).sum() <= 200


@pytest.mark.slow
def test_bound_merges_make_auto_smaller_than_births_alone(scene):
    counts = {}
    for merge in (True, False):
        config = mapping.Config(components="auto", growth=mapping.GrowthConfig(
            merge=merge, auto_merge_every=4, split=False))  # merges on, no splits
        state = mapping.init(config, key=jax.random.key(0))
        for frame in scene.train:
            state, _ = mapping.update(state, frame, config)
        counts[merge] = int(grow.is_active(state.mixture.prior).sum())
    # measured 399 with merges, 423 without
    assert counts[True] <= counts[False] - 15
    np.testing.assert_array_less(0, counts[True])
