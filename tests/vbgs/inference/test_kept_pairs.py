"""vbgs.inference.kept_pairs: the merge's pairs and costs redone only where components
changed give the from-scratch answer (merge.neighbour_pairs, merge.merge_costs,
merge.choose_pairs) to the bit, over a stream of changes."""

import numpy as np

from vbgs.inference import kept_pairs, merge, model
from vbgs.inference.model import PriorConfig

CONFIG = PriorConfig()
K = 400


def _posterior(means, scale, colours):
    prior = model.make_prior(means, colours, np.zeros(3, np.float32), 0.05, CONFIG)
    return prior._replace(space=prior.space._replace(scale=scale))


def _stream(seed: int = 0, steps: int = 8):
    """Posteriors, counts and active masks of a map whose components change a share at a
    time: some move a little (and change shape and count), some leave, some arrive."""
    rng = np.random.default_rng(seed)
    uv = rng.uniform(-1.0, 1.0, (K, 2))  # a wavy surface, as a map's components lie
    means = np.stack([uv[:, 0], uv[:, 1], 0.1 * np.sin(3 * uv[:, 0])], 1).astype(np.float32)
    colours = rng.uniform(0.0, 1.0, (K, 3)).astype(np.float32)
    base = model.make_prior(means, colours, np.zeros(3, np.float32), 0.05, CONFIG)
    scale = np.array(base.space.scale) * rng.uniform(0.5, 2.0, (K, 1, 1)).astype(np.float32)
    counts = rng.integers(0, 50, K).astype(np.float64)
    active = rng.random(K) < 0.8
    for _ in range(steps):
        yield _posterior(means, scale, colours), counts.copy(), active.copy()
        seen = rng.random(K) < 0.3  # the components a frame sees
        means = means.copy()
        means[seen] += rng.normal(0.0, 0.02, (seen.sum(), 3)).astype(np.float32)
        scale = scale.copy()
        scale[seen] *= np.float32(1.01)
        counts = counts.copy()
        counts[seen] += rng.integers(0, 5, seen.sum())
        colours = colours.copy()
        colours[seen[:K // 2].nonzero()[0]] *= np.float32(0.99)
        flip = rng.random(K) < 0.03  # merged away, or grown
        active = active ^ flip


def test_kept_pairs_and_costs_are_the_from_scratch_ones_over_a_stream(monkeypatch):
    kept_pairs._last[0] = None
    scored, costs = [], merge.merge_costs

    def counted(posterior, counts, pairs, noise):
        scored.append(len(pairs))
        return costs(posterior, counts, pairs, noise)

    for step, (posterior, counts, active) in enumerate(_stream()):
        scored.clear()
        with monkeypatch.context() as m:
            m.setattr(merge, "merge_costs", counted)
            pairs, cost = kept_pairs.pairs_and_costs(posterior, counts, active, 0.1)
        assert sum(scored) == len(pairs) if step == 0 else sum(scored) < 0.8 * len(pairs)
        want = merge.neighbour_pairs(posterior, active)
        assert np.array_equal(pairs, want)
        assert cost.tobytes() == merge.merge_costs(posterior, counts, want, 0.1).tobytes()
        got = kept_pairs.choose_pairs(posterior, counts, active, 30, 0.1)
        assert np.array_equal(got, merge.choose_pairs(posterior, counts, active, 30, 0.1))


def test_another_map_or_setting_is_redone_from_scratch():
    kept_pairs._last[0] = None
    first, second = _stream(1, 1), _stream(2, 1)
    for posterior, counts, active in (*first, *second):
        for noise in (0.1, 0.2):
            pairs, cost = kept_pairs.pairs_and_costs(posterior, counts, active, noise)
            want = merge.merge_costs(posterior, counts, pairs, noise)
            assert np.array_equal(pairs, merge.neighbour_pairs(posterior, active))
            assert cost.tobytes() == want.tobytes()
    one = np.zeros(K, bool)
    one[3] = True  # one active component: no pairs, and nothing kept
    pairs, cost = kept_pairs.pairs_and_costs(posterior, counts, one, 0.1)
    assert pairs.shape == (0, 2) and cost.shape == (0,) and kept_pairs._last[0] is None
