"""Pipelined frames (vbgs.mapping.update's ``defer``): what a frame's see-throughs forget
is decided at the next frame's growth, and the stream learns what it learns without,
to the bit, in frames that forget and merge as in those that do not."""

import jax
import numpy as np
import pytest

from vbgs import mapping
from vbgs.data.synthetic import changing_scene

SIZE, FRAMES, K = 64, 24, 2000  # few slots: the second lap merges as it forgets


@pytest.fixture(scope="module")
def changed():
    return changing_scene("room", size=SIZE, n_train=FRAMES, n_test=1, n_val=0)


CONFIG = mapping.Config(components=K)


def stream(frames, defer: bool):
    """The map after each frame (settled), the frames whose see-throughs forgot and
    those that merged."""
    state, forgot, merged, maps = mapping.init(CONFIG, key=jax.random.key(0)), [], [], []
    for i, frame in enumerate(frames):
        before = mapping.settled(state, CONFIG)
        state, _ = mapping.update(state, frame, CONFIG, defer=defer)
        assert state.unjudged == defer
        now = mapping.settled(state, CONFIG)
        if now.n_forgotten > before.n_forgotten:
            forgot.append(i)
        if now.n_merge_rounds > before.n_merge_rounds:
            merged.append(i)
        maps.append(now)
    return maps, forgot, merged


def leaves(state):
    return [np.asarray(a) for a in jax.tree_util.tree_leaves(
        (state.mixture, state.evidence, state.colour, state.doubt))]


def test_a_deferred_stream_learns_what_a_settled_one_learns_to_the_bit(changed):
    deferred, forgot, merged = stream(changed.train, defer=True)
    direct, *rest = stream(changed.train, defer=False)
    assert rest == [forgot, merged]
    # a frame after one that forgot grows twice; some of them merge in both growths
    assert {i + 1 for i in forgot} & set(merged)
    for a, b in zip(deferred, direct, strict=True):
        assert (a.n_forgotten, a.n_merged, a.n_points) == (b.n_forgotten, b.n_merged,
                                                           b.n_points)
        for x, y in zip(leaves(a), leaves(b), strict=True):
            np.testing.assert_array_equal(x, y)


def test_an_unjudged_map_is_read_as_settled(changed, tmp_path):
    bound = mapping.mapper(CONFIG)
    state = bound.init(key=jax.random.key(0))
    for frame in changed.train[:FRAMES // 2 + 3]:  # into the second lap: doubts counted
        state, _ = bound.update(state, frame, defer=True)
    assert state.unjudged
    judged = bound.settled(state)
    assert not judged.unjudged and mapping.settled(judged, CONFIG) is judged
    with pytest.raises(ValueError, match="not settled"):
        mapping.save(tmp_path / "map.npz", state)
    for a, b in zip(jax.tree_util.tree_leaves(mapping.splats(state, CONFIG)),
                    jax.tree_util.tree_leaves(mapping.splats(judged, CONFIG)), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    frame = changed.train[FRAMES // 2 + 3]
    xyz = np.asarray(judged.mixture.posterior.space.mean)[:50] + np.asarray(
        judged.mixture.prior.origin)
    rgb = np.full((50, 3), 0.5, np.float32)
    a, _ = mapping.update_points(state, xyz, rgb, CONFIG, camera=frame.camera)
    b, _ = mapping.update_points(judged, xyz, rgb, CONFIG, camera=frame.camera)
    for x, y in zip(leaves(a), leaves(b), strict=True):
        np.testing.assert_array_equal(x, y)
