"""components="auto": the split rule (vbgs.mapping.splits) through the stream loop.

A flat patch of 40 x 40 points learned four times: the first batch grows level-0
components (about growth.auto_points points each); once its cells have shown enough
points (four of each: the Bayes factor of a child then pays for its parameters) the
components whose colour they explain badly are split, never finer than the pixel
footprint allows and never past the ceiling auto:MAX.
"""

import jax
import numpy as np
import pytest

from vbgs import mapping
from vbgs.inference import grow

SIDE = 40  # points a side of the patch


def patch(checker: bool, seed: int = 0):
    """``[n, 3]`` points of a flat patch 3 units in front of the origin, their colours:
    red and blue alternating point by point (each component holds both: badly explained)
    or one grey with 0.01 noise (well explained)."""
    g = np.linspace(-0.45, 0.45, SIDE)
    x, y = np.meshgrid(g, g)
    xyz = np.stack([x.ravel(), y.ravel(), np.full(x.size, 3.0)], 1).astype(np.float32)
    if checker:
        odd = ((np.arange(SIDE)[:, None] + np.arange(SIDE)[None, :]) % 2).ravel()
        rgb = np.where(odd[:, None] == 1, [0.9, 0.1, 0.1], [0.1, 0.1, 0.9])
    else:
        rgb = 0.5 + 0.01 * np.random.default_rng(seed).standard_normal((len(xyz), 3))
    return xyz, rgb.astype(np.float32)


def active_after(config, xyz, rgb, footprint=None, batches=4):
    """Active components after each of ``batches`` batches of the same points."""
    state = mapping.init(config, key=jax.random.key(0))
    counts = []
    for _ in range(batches):
        state, _ = mapping.update_points(state, xyz, rgb, config, footprint=footprint)
        counts.append(int(grow.is_active(state.mixture.prior).sum()))
        assert grow.is_active(state.mixture.prior).sum() <= state.mixture.prior.n_components
    return counts, state


def auto(gain=0.0, floor=1.0, components="auto", split=True, shape=False):
    return mapping.Config(components=components, growth=mapping.GrowthConfig(
        split=split, refine_gain=gain, refine_footprints=floor, merge=False,
        refine_shape=shape))


def test_a_patch_whose_colours_its_components_mix_is_split_once_the_evidence_pays():
    counts, _ = active_after(auto(), *patch(checker=True))
    # measured: 400 level-0 components (1600 points, 4 a cell), 434 and 448 (new ground
    # only: a level-1 cell holds one point, and one or two showings of it do not pay
    # for a child's parameters), then 1308 at the fourth (4 showings: 1.44 nats)
    assert counts == [400, 434, 448, 1308]


def test_a_patch_its_components_explain_is_not_split():
    counts, _ = active_after(auto(), *patch(checker=False))
    assert counts == [400] * 4  # grey within 0.01: the evidence only falls


def test_the_shape_term_adds_no_child_on_a_flat_patch():
    """growth.refine_shape through the stream: on a flat grey patch the shape term is 0
    (vbgs.mapping.splits.surface_gain), so nothing splits; the checkerboard still does."""
    counts, state = active_after(auto(shape=True), *patch(checker=False))
    assert counts == [400] * 4 and state.colours.place is not None
    counts, _ = active_after(auto(shape=True), *patch(checker=True))
    assert counts[-1] > 2 * counts[0]


def test_without_the_rule_the_resolution_is_the_first_frame_s():
    counts, _ = active_after(auto(split=False), *patch(checker=True))
    # new ground only (the colours pull the means about, so a few level-0 cells are
    # left without one), no refinement
    assert counts[0] == 400 and counts[-1] < 1.2 * counts[0]


def test_no_split_finer_than_the_pixel_footprint():
    xyz, rgb = patch(checker=True)
    # the level-0 cell is ~0.045 (0.9^2 / 400 cells): footprints of 0.05 leave no level
    # of side >= one footprint below it; footprints of 0.01 leave two (0.0225, 0.011)
    coarse, _ = active_after(auto(), xyz, rgb, np.full(len(xyz), 0.05, np.float32))
    assert coarse[-1] < 1.2 * coarse[0]  # new ground only, as without the rule
    fine, _ = active_after(auto(), xyz, rgb, np.full(len(xyz), 0.01, np.float32))
    assert fine[-1] >= 2 * fine[0]


def test_splits_keep_to_the_ceiling():
    counts, state = active_after(auto(components="auto:500"), *patch(checker=True))
    # the first batch may add half of MAX (the bounded rate): 250; the splits fill up to MAX
    assert counts[0] == 250 and 250 < counts[-1] <= 500
    assert state.mixture.prior.n_components == 500


def test_split_children_get_their_own_cell_s_prior_scale():
    config = auto()
    xyz, rgb = patch(checker=True)
    counts, state = active_after(config, xyz, rgb)
    first = counts[0]
    prior = state.mixture.prior
    active = np.flatnonzero(grow.is_active(prior))
    # the trace of a slot's NIW scale: level-0 components have one value (flattened along
    # the patch's normal), children 4^-l of it for their level l >= 1
    trace = np.trace(np.asarray(prior.space.scale, np.float64)[active], axis1=1, axis2=2)
    level0 = np.median(trace[:first])
    ratios = trace[first:] / level0
    assert np.allclose(trace[:first], level0, rtol=1e-3)
    levels = -np.log(ratios) / np.log(4.0)
    np.testing.assert_allclose(levels, np.round(levels), atol=1e-3)
    # children at levels 1..LEVELS-1; level 0: later batches' few new-ground births
    assert set(np.round(levels).astype(int)) <= set(range(grow.LEVELS))
    assert (np.round(levels) >= 1).sum() >= first


def test_refine_gain_is_checked():
    with pytest.raises(ValueError, match="refine_gain"):
        mapping.GrowthConfig(refine_gain=float("inf"))
    with pytest.raises(ValueError, match="split"):
        mapping.GrowthConfig(split=1)
    with pytest.raises(ValueError, match="refine_footprints"):
        mapping.GrowthConfig(refine_footprints=0.0)
