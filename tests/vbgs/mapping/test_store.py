"""vbgs.mapping.save / load: a stream resumed from a saved map equals the uninterrupted one."""

import jax
import numpy as np
import pytest

from vbgs import mapping
from vbgs.data.formats import load_scene


@pytest.fixture(scope="module")
def scene():
    return load_scene("object", size=32, n_train=10, n_test=1, seed=0)


def _leaves_equal(a, b):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    assert len(la) == len(lb)
    for u, v in zip(la, lb, strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))


@pytest.mark.parametrize("search,held", [("kdtree", False), ("projective", False),
                                         ("kdtree", True)])
def test_a_resumed_stream_equals_the_uninterrupted_one_to_the_bit(scene, tmp_path, search,
                                                                   held):
    """``held``: the walk on a budget its first frame half spends, with growth's held
    ground (seeds and what merges emptied, ``growth.hold_*``) carried in the saved map."""
    config = mapping.Config(components=600, search=search)
    if held:
        config = mapping.Config(components=400, search=search, growth=mapping.GrowthConfig(
            first_frame_share=0.5, hold_seeds=True, hold_paid=True))
        scene = load_scene("walk", size=32, n_train=10, n_test=1, seed=0)
    learner = mapping.mapper(config)
    state = learner.init(key=jax.random.key(3))
    for frame in scene.train[:5]:
        state, _ = learner.update(state, frame)
    path = mapping.save(tmp_path / "map", state)
    assert path.name == "map.npz"
    whole = state
    for frame in scene.train[5:]:
        whole, _ = learner.update(whole, frame)
    resumed = mapping.load(path, config)
    assert resumed.n_frames == 5 and resumed.rule == state.rule
    for frame in scene.train[5:]:
        resumed, _ = learner.update(resumed, frame)
    _leaves_equal(whole.mixture, resumed.mixture)
    _leaves_equal(whole.evidence, resumed.evidence)
    np.testing.assert_array_equal(jax.random.key_data(whole.key),
                                  jax.random.key_data(resumed.key))
    assert (whole.n_points, whole.n_unlearned) == (resumed.n_points, resumed.n_unlearned)
    _leaves_equal(learner.splats(whole), learner.splats(resumed))
    if held:
        assert state.paid is not None and whole.n_merged > state.n_merged > 0
        np.testing.assert_array_equal(whole.paid, resumed.paid)


def test_a_map_before_any_frame_round_trips(tmp_path):
    config = mapping.Config(components=50)
    state = mapping.init(config, key=jax.random.key(0))
    loaded = mapping.load(mapping.save(tmp_path / "empty.npz", state), config)
    assert loaded.mixture is None and loaded.growing and loaded.n_frames == 0


def test_bad_files_are_refused_clearly(tmp_path):
    config = mapping.Config(components=50)
    with pytest.raises(FileNotFoundError, match="no saved map at"):
        mapping.load(tmp_path / "missing.npz", config)
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(ValueError, match="is not a saved map"):
        mapping.load(tmp_path / "other.npz", config)
