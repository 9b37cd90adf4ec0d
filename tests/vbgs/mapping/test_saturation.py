"""Points already explained are skipped (vbgs.mapping.saturation): a cell takes about N
points over a stream, a cell never seen keeps its points, and through the mapper a frame
seen again costs only the points of its unlearned cells."""

import jax
import numpy as np

from vbgs.data.scene import Frame
from vbgs.inference import grow
from vbgs.mapping import BudgetConfig, Config, init, saturation, update
from vbgs.render.camera import from_fov, look_at

RULE = grow.Growth(cell=0.5, levels=1, refine=0.0, max_new=100)


def test_cell_keys_tell_cells_and_levels_apart():
    xyz = np.array([[0.1, 0.1, 0.1], [0.4, 0.2, 0.3], [0.6, 0.1, 0.1], [-0.1, 0.1, 0.1],
                    [0.1, -0.1, 0.1], [0.1, 0.1, 0.1]])
    keys = saturation.cell_keys(RULE, xyz, np.zeros(3), np.array([0, 0, 0, 0, 0, 1]))
    assert keys[0] == keys[1]  # one cell
    assert len(set(keys[[0, 2, 3, 4, 5]].tolist())) == 5  # neighbours, negatives, a level


def test_a_new_cell_keeps_about_n_points_and_a_full_one_none():
    keys = np.zeros(1000, np.int64) + 7  # 1000 points of one cell, never seen
    seen = saturation.nothing_seen(10)
    kept = saturation.keep(seen, keys, 16, key=jax.random.key(0))
    assert 6 <= kept.sum() <= 30  # binomial(1000, 16/1000): mean 16
    seen = saturation.add(seen, keys[kept])
    assert seen.count.sum() == kept.sum()
    full = saturation.add(seen, keys[:16])  # now over 16 points: saturated
    assert not saturation.keep(full, keys, 16, key=jax.random.key(1)).any()
    # a few points of a cell seen a little: all of them fit under the cap
    few = saturation.add(saturation.nothing_seen(10), keys[:3])
    assert saturation.keep(few, keys[:13], 16, key=jax.random.key(2)).all()


def test_a_clash_in_the_table_counts_as_unseen():
    """A cell whose slot counts another cell keeps its points (a clash costs time, never
    a point of unseen ground), and takes the slot over when counted."""
    bits = 4
    slots = saturation._slots(np.arange(1, 400, dtype=np.int64), bits)
    a, b = np.flatnonzero(slots == slots[0])[:2] + 1  # two cells in one slot
    seen = saturation.add(saturation.nothing_seen(bits), np.full(50, a, np.int64))
    assert not saturation.keep(seen, np.full(5, a, np.int64), 8, key=jax.random.key(0)).any()
    assert saturation.keep(seen, np.full(5, b, np.int64), 8, key=jax.random.key(0)).all()
    seen = saturation.add(seen, np.full(3, b, np.int64))
    slot = saturation._slots(np.array([b]), bits)[0]
    assert seen.cell[slot] == b and seen.count[slot] == 3


W, H = 48, 32


def wall_frame() -> Frame:
    cam = from_fov(W, H, 1.2, look_at((0.0, -2.0, 0.5), (0.0, 0.0, 0.5)))
    u, v = np.meshgrid(np.linspace(0, 1, W), np.linspace(0, 1, H))
    rgb = np.stack([u, v, 0.5 * (u + v)], -1).astype(np.float32)
    return Frame(rgb, np.full((H, W), 2.0, np.float32), cam)


def test_a_frame_seen_again_learns_only_unsaturated_cells():
    """A wall seen twice by a growing map: the first frame is learned whole; with N = 4
    points per cell the second skips all but one point (each cell holds dozens of the
    first frame's) and counts them; N = 0 learns both frames whole."""
    f = wall_frame()

    def run(n):
        config = Config(components=200, estep="sparse",
                        budget=BudgetConfig(saturation=n))
        state = init(config, key=jax.random.key(0))
        state, first = update(state, f, config)
        state, second = update(state, f, config)
        return state, first, second

    full, f0, s0 = run(0)
    capped, f4, s4 = run(4)
    assert f0.n_points == f4.n_points == W * H and s0.n_points == W * H
    assert s4.n_points <= 3 and capped.n_skipped == W * H - s4.n_points
    assert capped.n_points + capped.n_skipped == 2 * W * H
    # the one point the second frame kept (a frame's step needs one) barely moves the
    # posterior it was learned from
    moved = np.abs(np.asarray(capped.mixture.posterior.space.mean)
                   - np.asarray(s4.before.space.mean)).max()
    assert moved < 1e-3
