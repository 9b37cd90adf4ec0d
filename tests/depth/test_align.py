import numpy as np
import pytest

from depth import Alignment, OnnxDepth, align, apply, median_scale, scale_shift
from depth.testing import depth_lookup_model, distorted_depth

H, W = 96, 128
FRACTION = 0.01  # of the pixels carry reference depth
OUTLIERS = 0.20  # of those reference pixels are replaced by garbage
TOLERANCE = 0.01  # relative error allowed on the recovered scale and shift


def _scene(m=3, seed=0):
    """RGB frames in [0, 1] and smooth depth in [1, 5] m with a missing corner."""
    rng = np.random.default_rng(seed)
    rgb = rng.random((m, H, W, 3), dtype=np.float32)
    v, u = np.mgrid[0:H, 0:W] / np.array([H, W])[:, None, None]
    depth = np.stack([1.0 + 4.0 * (0.5 + 0.5 * np.sin(3 * u + 2 * v + k)) for k in range(m)])
    depth[:, :8, :8] = 0.0
    return rgb, depth.astype(np.float32)


def _sparse_reference(depth, seed=1):
    """Flat indices of 1% of the valid pixels; 20% of them get wrong depth."""
    rng = np.random.default_rng(seed)
    valid = np.flatnonzero(depth.ravel() > 0)
    idx = rng.choice(valid, int(FRACTION * depth.size), replace=False)
    ref = np.zeros_like(depth)
    ref.flat[idx] = depth.flat[idx]
    bad = rng.choice(idx, int(OUTLIERS * len(idx)), replace=False)
    ref.flat[bad] = rng.uniform(0.2, 20.0, len(bad))
    return ref, idx


def test_depth_lookup_model_returns_the_stored_distortion_of_the_nearest_frame():
    rgb, depth = _scene()
    model = OnnxDepth(depth_lookup_model(rgb, depth, 2.0, 0.5, 0.01, 7).SerializeToString(),
                      kind="inverse")
    table = distorted_depth(depth, 2.0, 0.5, 0.01, 7)
    for k in (2, 0):
        np.testing.assert_array_equal(model.predict(rgb[k]), table[k])
    np.testing.assert_array_equal(model.predict(rgb[[1, 2]]), table[[1, 2]])
    assert (table[:, :8, :8] == 0).all()
    valid = depth > 0
    clean = 2.0 / depth[valid] + 0.5
    assert 0.005 < np.std(table[valid] - clean) < 0.02  # the seeded noise is there


# (lookup space, lookup scale a, shift b, method, align space): prediction p = a f(d) + b
CASES = [
    ("inverse", 2.0, 0.5, "scale-shift-inverse", None),  # 1/d = (p - b) / a
    ("depth", 0.5, 0.2, "scale-shift", None),  # d = (p - b) / a
    ("inverse", 2.0, 0.0, "median", "inverse"),
    ("depth", 0.5, 0.0, "median", "depth"),
]


@pytest.mark.parametrize("space, a, b, method, median_space", CASES)
def test_alignment_recovers_known_scale_and_shift_despite_outliers(space, a, b, method,
                                                                   median_space):
    rgb, depth = _scene()
    model_bytes = depth_lookup_model(rgb, depth, a, b, 1e-3, 0, space=space).SerializeToString()
    model = OnnxDepth(model_bytes, kind="inverse" if space == "inverse" else "relative")
    pred = model.predict(rgb[1])
    ref, idx = _sparse_reference(depth[1])
    fit = align(pred, ref, idx, method, space=median_space)
    true_scale, true_shift = 1.0 / a, -b / a
    assert fit.space == space and fit.n_points == len(idx)
    assert abs(fit.scale - true_scale) <= TOLERANCE * abs(true_scale)
    assert abs(fit.shift - true_shift) <= TOLERANCE * max(abs(true_shift), 1e-12)
    assert 0.75 <= fit.inlier_fraction <= 0.85 and fit.residual < 0.01
    metric = apply(fit, pred)
    valid = depth[1] > 0
    assert np.median(np.abs(metric[valid] - depth[1][valid]) / depth[1][valid]) < 0.01
    assert (metric[~valid] == 0).all()  # missing depth stays missing


def test_alignment_is_exact_on_clean_data_and_deterministic():
    rng = np.random.default_rng(5)
    d = rng.uniform(0.5, 8.0, 500)
    p = (1.0 / d - 0.05) / 0.3
    fit = align(p, d, method="scale-shift-inverse", seed=3)
    assert fit == align(p, d, method="scale-shift-inverse", seed=3)
    np.testing.assert_allclose([fit.scale, fit.shift], [0.3, 0.05], rtol=1e-9)
    assert fit.inlier_fraction == 1.0 and fit.residual < 1e-6  # float32 apply


def test_mask_forms_agree():
    rng = np.random.default_rng(2)
    d = rng.uniform(1, 4, (10, 12))
    p = 2.0 * d - 1.0
    mask = rng.random((10, 12)) < 0.3
    by_bool = scale_shift(p, d, mask)
    assert by_bool == scale_shift(p, d, np.flatnonzero(mask))
    assert by_bool == scale_shift(p, d, np.nonzero(mask))
    np.testing.assert_allclose([by_bool.scale, by_bool.shift], [0.5, 0.5], rtol=1e-9)


def test_apply_turns_impossible_depth_into_missing():
    inverse = Alignment(1.0, -1.0, "inverse", 0.0, 1.0, 0)
    out = apply(inverse, np.array([0.5, 1.0, 3.0, np.inf, np.nan]))
    np.testing.assert_array_equal(out, [0.0, 0.0, 0.5, 0.0, 0.0])
    assert out.dtype == np.float32
    depth = Alignment(2.0, -1.0, "depth", 0.0, 1.0, 0)
    np.testing.assert_array_equal(apply(depth, np.array([0.25, 1.0])), [0.0, 1.0])


def test_clear_errors():
    d = np.ones((4, 4))
    with pytest.raises(ValueError, match="only 0 usable reference pixels"):
        median_scale(np.ones((4, 4)), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="constant over the reference pixels"):
        scale_shift(np.ones((4, 4)), d)
    with pytest.raises(ValueError, match="same shape"):
        align(np.ones((4, 4)), np.ones((4, 5)))
    with pytest.raises(ValueError, match="unknown alignment method"):
        align(np.ones((4, 4)), d, method="magic")
