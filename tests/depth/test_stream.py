"""Depth for a stream is aligned from arrived frames only, in arrival order."""

import numpy as np
import pytest

from depth.stream import StreamConfig, arrive, finish, init
from vbgs.data.synthetic import make_scene


@pytest.fixture(scope="module")
def frames():
    return make_scene("object", size=24, n_train=6, n_test=1, seed=0, n_val=0).train


def _prediction(frame, k):
    """Relative depth ``k * depth`` (a model off by a factor k), sky at 3 times the max."""
    d = np.where(frame.depth > 0, frame.depth, 3.0 * frame.depth.max())
    return (k * d).astype(np.float32)


def _stream(frames, order, config, k, truth=None):
    """Stream ``frames`` in ``order``, each with the prediction of ``truth`` (default: the
    frames themselves); the state, the count released at each arrival and at the end."""
    truth = frames if truth is None else truth
    state, out = init(), []
    for i in order:
        state, ready = arrive(state, frames[i], _prediction(truth[i], k[i]), config)
        out.append(len(ready))
    state, ready = finish(state, config)
    return state, out, len(ready)


def test_sensor_reference_reads_the_first_arrived_frame(frames):
    k = np.linspace(1.0, 2.0, len(frames))  # frame i's model is off by k[i]
    config = StreamConfig(kind="relative", method="median", reference="sensor")
    for order in (range(6), range(5, -1, -1)):
        state, released, _ = _stream(frames, list(order), config, k)
        first = list(order)[0]
        assert state.aligned_on == (0,) and state.reference == "sensor"
        # median scale: d = p / k of the frame it read, exactly
        assert state.alignment.scale == pytest.approx(1.0 / k[first], rel=1e-6)
        assert released == [1] * 6  # nothing held: the first frame has depth


def test_views_reference_holds_frames_until_they_arrive(frames):
    rgb_only = [f._replace(depth=np.zeros_like(f.depth)) for f in frames]
    config = StreamConfig(kind="relative", reference="auto", views=3)
    state, released, at_end = _stream(rgb_only, [5, 4, 3, 2, 1, 0], config, np.ones(6),
                                      frames)
    assert state.reference == "views" and state.aligned_on == (0, 1, 2)
    assert released == [0, 0, 3, 1, 1, 1] and at_end == 0


def test_a_short_stream_aligns_on_what_arrived_and_one_view_is_refused(frames):
    rgb_only = [f._replace(depth=np.zeros_like(f.depth)) for f in frames]
    config = StreamConfig(kind="relative", reference="views", views=6)
    state = init()
    state, ready = arrive(state, rgb_only[0], _prediction(frames[0], 1.0), config)
    assert ready == [] and state.alignment is None
    with pytest.raises(ValueError, match="at least 2 views"):
        finish(state, config)


def test_sensor_reference_without_sensor_depth_is_refused(frames):
    rgb_only = [f._replace(depth=np.zeros_like(f.depth)) for f in frames[:2]]
    config = StreamConfig(kind="relative", reference="sensor")
    state, _, _ = init(), None, None
    for f, seen in zip(rgb_only, frames[:2], strict=True):  # the model sees the scene
        state, ready = arrive(state, f, _prediction(seen, 1.0), config)
        assert ready == []
    with pytest.raises(ValueError, match="--depth-reference views"):
        finish(state, config)


@pytest.mark.parametrize("value, words", [
    (1e9, "the model's output is 1e+09 at every finite pixel"),
    (float("nan"), "NaN or infinite at all"), (-1.0, "no pixel is > 0"),
    (0.0, "spans 0 to 0: no pixel is > 0")], ids=["1e9", "nan", "negative", "zero"])
def test_a_prediction_that_is_no_depth_is_refused_naming_it(frames, value, words):
    config = StreamConfig(kind="relative", reference="views")
    with pytest.raises(ValueError, match=words.replace("+", r"\+")):
        arrive(init(), frames[0], np.full_like(frames[0].depth, value), config)


def test_metric_model_is_not_aligned_and_its_sky_is_cut(frames):
    config = StreamConfig(kind="metric")
    state, ready = arrive(init(), frames[0], _prediction(frames[0], 1.0), config)
    (frame, depth), = ready
    assert state.reference == "metric" and state.aligned_on == ()
    assert np.all(depth[frames[0].depth == 0] == 0)  # the sky (3 x max) is not surface
    kept = depth > 0
    assert np.allclose(depth[kept], frames[0].depth[kept])
