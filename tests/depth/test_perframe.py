"""Each frame's depth is aligned to the frames that arrived before it, and to no other."""

import numpy as np
import pytest

from depth.perframe import FrameAlignConfig, Reference, align_frame, apply, fit, init
from depth.stream import StreamConfig, arrive, finish
from depth.stream import init as stream_init
from experiments.tasks.sensor_swap import AlignedArrivals
from vbgs.data.synthetic import make_scene

# no pull toward the frame as it came: the references are the truth here
EXACT = FrameAlignConfig(warp_order=0, ridge=0.0, shift_ridge=0.0, shrink=0.0)


@pytest.fixture(scope="module")
def frames():
    return make_scene("object", size=32, n_train=8, n_test=1, seed=0, n_val=0).train


def _rel_error(depth, truth):
    ok = (depth > 0) & (truth > 0)
    return float(np.median(np.abs(depth[ok] / truth[ok] - 1.0)))


def test_a_known_scale_and_shift_are_recovered(frames):
    ref, target = frames[0], frames[1]
    wrong = np.where(target.depth > 0, 1.04 * target.depth + 0.03, 0.0)  # 4 %, 3 cm
    assert _rel_error(wrong, target.depth) > 0.04
    f = fit(wrong, target.camera, [Reference(ref.camera, ref.depth)], EXACT)
    assert f.n_pairs > 100
    assert _rel_error(apply(f, wrong, 0), target.depth) < 0.002


def test_a_smooth_warp_is_recovered_by_the_linear_terms(frames):
    ref, target = frames[0], frames[1]
    h, w = target.depth.shape
    x = ((np.arange(w) + 0.5) / w * 2 - 1)[None, :]
    wrong = np.where(target.depth > 0, target.depth * (1.03 + 0.02 * x), 0.0)
    config = EXACT._replace(warp_order=1)
    f = fit(wrong, target.camera, [Reference(ref.camera, ref.depth)], config)
    assert _rel_error(apply(f, wrong, 1), target.depth) < 0.003
    scale_only = fit(wrong, target.camera, [Reference(ref.camera, ref.depth)], EXACT)
    assert _rel_error(apply(scale_only, wrong, 0), target.depth) > 0.005


def test_shrink_one_goes_half_way_to_the_references(frames):
    ref, target = frames[0], frames[1]
    wrong = np.where(target.depth > 0, 1.04 * target.depth, 0.0)
    config = EXACT._replace(shrink=1.0, shift_ridge=1e6)  # scale only, pulled toward 1
    f = fit(wrong, target.camera, [Reference(ref.camera, ref.depth)], config)
    assert f.coef[0] == pytest.approx(0.5 * (1.0 + 1 / 1.04), abs=0.003)


def test_no_overlap_leaves_the_frame_as_it_came(frames):
    f0 = frames[0]
    pose = np.array(f0.camera.pose, copy=True)
    pose[:3, 3] += 100.0  # a reference far away sees none of the target's points
    far = f0.camera._replace(pose=pose)
    state, out, fit_ = align_frame(init()._replace(frames=(Reference(far, f0.depth),)),
                                   f0.camera, 1.1 * f0.depth, FrameAlignConfig())
    assert fit_.coef == (1.0,) and fit_.shift == 0.0
    np.testing.assert_allclose(out, (1.1 * f0.depth).astype(np.float32), rtol=1e-6)


def _scaled(frames, k):
    return [f._replace(depth=(k[i] * f.depth).astype(np.float32)) for i, f in enumerate(frames)]


def _stream(frames, order, config):
    stage = AlignedArrivals(config, {})
    return {i: f.depth for i, f in zip(order, stage(frames[i] for i in order), strict=True)}


def test_a_stream_aligns_on_its_own_first_frames(frames):
    k = np.ones(len(frames))
    k[-1] = 1.05  # the last file's depth is 5 % too far
    data = _scaled(frames, k)
    forward = _stream(data, list(range(len(frames))), EXACT)
    for i in range(len(frames)):  # the first arrived frame is right: all end up right,
        assert _rel_error(forward[i], frames[i].depth) < 0.006, i  # the last one too
    order = list(range(len(frames)))[::-1]
    backward = _stream(data, order, EXACT)
    first, second = order[0], order[1]
    np.testing.assert_array_equal(backward[first], data[first].depth)  # left as it came
    # the second arrival is fitted to the first arrival alone (the last file), so it
    # follows that frame's error, not the frames that arrive after it
    alone = fit(data[second].depth, data[second].camera,
                [Reference(data[first].camera, data[first].depth)], EXACT)
    np.testing.assert_allclose(backward[second], apply(alone, data[second].depth, 0),
                               rtol=1e-6)
    assert _rel_error(backward[second], frames[second].depth) > 0.01


def test_the_stage_never_reads_a_frame_before_it_arrives(frames):
    pulled = []

    def source():
        for i, f in enumerate(frames):
            pulled.append(i)
            yield f

    stage = AlignedArrivals(FrameAlignConfig(), {"depth_sensor": "mono"})
    out = stage(source())
    for n in range(1, len(frames) + 1):
        next(out)
        assert len(pulled) == n  # the n-th aligned frame was made from n arrived frames
    report = stage.report()
    assert report["depth_sensor"] == "mono"
    assert report["depth_per_frame_aligned"] == len(frames) - 1  # all but the first


def test_the_aligner_keeps_only_its_window(frames):
    state = init()
    config = FrameAlignConfig(window=3)
    for f in frames:
        state, _, _ = align_frame(state, f.camera, f.depth, config)
    assert len(state.frames) == 3 and state.arrived == len(frames)
    assert state.frames[-1].camera is frames[-1].camera


def test_a_depth_model_stream_aligns_each_released_frame(frames):
    """depth.stream runs the same per-frame alignment on what it releases: a metric
    model whose second frame is 5 % too far comes out right, its first as it came."""
    k = np.ones(len(frames))
    k[1] = 1.05
    config = StreamConfig(kind="metric", per_frame=EXACT)
    state, out = stream_init(), []
    for f, kf in zip(frames[:3], k, strict=False):
        pred = np.where(f.depth > 0, kf * f.depth, 3.0 * f.depth.max()).astype(np.float32)
        state, ready = arrive(state, f._replace(depth=np.zeros_like(f.depth)), pred, config)
        out += ready
    state, ready = finish(state, config)
    out += ready
    assert len(out) == 3 and len(state.fits) == 3 and state.fits[0].n_pairs == 0
    assert _rel_error(out[1][1], frames[1].depth) < 0.006
    unaligned = StreamConfig(kind="metric", per_frame=None)
    state, ready = arrive(stream_init(), frames[1], (1.05 * frames[1].depth), unaligned)
    assert _rel_error(ready[0][1], frames[1].depth) > 0.04 and state.fits == ()
