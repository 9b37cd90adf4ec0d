"""components="auto": the split rule's evidence (vbgs.mapping.splits).

The colour log Bayes factor against a brute-force integral of its two marginal
likelihoods; the rule on a flat-coloured plane, a checkerboard and texture finer than the
cell; the table's sums over batches and its clashes."""

import numpy as np
from scipy import integrate
from scipy.special import gammaln

from vbgs.inference import grow
from vbgs.inference.model import PriorConfig
from vbgs.mapping import splits

SIGMA, STRENGTH = 0.05, 1.0


def brute_log_bf(c, m, sigma=SIGMA, strength=STRENGTH):
    """log p(c | H1) - log p(c | H0) for 1-D colours ``c [n]``: the noise precision tau
    (Gamma(a0, b0)) integrated out by the Gamma integral, the child's mean mu ~ N(m,
    1/(lambda tau)) under H1 by quadrature."""
    a0 = 0.5 * strength
    b0 = a0 * sigma**2
    n = len(c)

    def gamma_integral(shape_extra, rss):  # int tau^(a0-1+extra) e^(-b0 tau - rss tau/2)
        return np.exp(gammaln(a0 + shape_extra) - gammaln(a0) + a0 * np.log(b0)
                      - (a0 + shape_extra) * np.log(b0 + 0.5 * rss))

    p0 = gamma_integral(0.5 * n, np.sum((c - m) ** 2)) * (2 * np.pi) ** (-0.5 * n)

    def joint(mu):  # p(c, mu | H1)
        rss = np.sum((c - mu) ** 2) + strength * (mu - m) ** 2
        return (gamma_integral(0.5 * (n + 1), rss) * np.sqrt(strength)
                * (2 * np.pi) ** (-0.5 * (n + 1)))

    p1 = sum(integrate.quad(joint, lo, hi, epsabs=0, epsrel=1e-10, limit=500)[0]
             for lo, hi in ((-np.inf, -1.0), (-1.0, 2.0), (2.0, np.inf)))  # colours in [0, 1]
    return np.log(p1) - np.log(p0)


def test_the_colour_bayes_factor_is_the_integral_of_its_marginal_likelihoods():
    rng = np.random.default_rng(0)
    for c in (0.5 + 0.2 * rng.random(3), 0.4 + 0.05 * rng.standard_normal(6),
              np.array([0.3])):
        m = 0.45
        closed = splits.log_bayes_factor(np.array([len(c)]), np.array([[c.sum()]]),
                                         np.array([np.sum(c**2)]), np.array([[m]]),
                                         colour_noise=SIGMA, strength=STRENGTH)[0]
        np.testing.assert_allclose(closed, brute_log_bf(c, m), atol=1e-5)


def score(c, m):
    """The rule's score of one cell of colours ``c [n, 3]`` against ``m [3]``: its colour
    log Bayes factor less the spatial Occam factor of a 3-D child."""
    n = np.array([len(c)], np.float64)
    colour = splits.log_bayes_factor(n, c.sum(0)[None], np.array([np.sum(c**2)]), m[None],
                                     colour_noise=SIGMA, strength=STRENGTH)
    return float((colour - splits.spatial_occam(n, 3, PriorConfig()))[0])


def test_a_flat_cell_never_earns_a_child_a_cell_its_component_misses_does():
    rng = np.random.default_rng(1)
    grey = np.full(3, 0.5)
    for n in (1, 4, 64, 1024):
        flat = grey + 0.01 * rng.standard_normal((n, 3))  # what the component explains
        assert score(flat, grey) < 0
    # half red half blue, the component purple: a child of a half would explain it; the
    # cell's own mean is purple too, so a child of the whole cell earns nothing...
    red, blue = np.array([0.9, 0.1, 0.1]), np.array([0.1, 0.1, 0.9])
    both = np.concatenate([np.tile(red, (32, 1)), np.tile(blue, (32, 1))])
    assert score(both, 0.5 * (red + blue)) < 0
    # ...while a cell of one half does, from a few points on: the miss grows as n, the
    # Occam factors as log n (measured, nats)
    got = [score(np.tile(red, (n, 1)), 0.5 * (red + blue)) for n in (1, 2, 3, 4, 32)]
    np.testing.assert_allclose(got, [-2.49, -2.30, -0.83, 1.44, 149.20], atol=0.01)


def test_texture_finer_than_the_cell_earns_nothing_however_many_points():
    """Colours scattered at twice sigma_c about the component's mean: the rule this
    replaced (one frame's colour gain at noise sigma_c, > 1 nat) split such a cell of 4
    points (its gain averages 6.3 nats); here the score is below zero and falls as the
    points add up (measured means over 20 draws: -3.2, -9.3, -25.8, -43.3 nats)."""
    rng = np.random.default_rng(2)
    m = np.full(3, 0.5)
    scores = [np.mean([score(m + 2 * SIGMA * rng.standard_normal((n, 3)), m)
                       for _ in range(20)]) for n in (1, 4, 64, 1024)]
    np.testing.assert_allclose(scores, [-3.22, -9.27, -25.79, -43.31], atol=0.01)


def test_the_table_sums_a_cell_over_batches_and_a_clash_starts_it_again():
    table = splits.no_colours(4)  # 16 slots
    keys = np.array([5, 5, 9], np.int64)
    rgb = np.array([[0.1, 0.2, 0.3], [0.3, 0.2, 0.1], [1.0, 1.0, 1.0]])
    table, slot = splits.add(table, keys, rgb)
    table, slot = splits.add(table, keys[:1], rgb[:1])
    np.testing.assert_allclose(table.count[slot[0]], 3)
    np.testing.assert_allclose(table.total[slot[0]], [0.5, 0.6, 0.7], rtol=1e-6)
    np.testing.assert_allclose(table.square[slot[0]], 0.14 * 2 + 0.14, rtol=1e-6)
    # a key that hashes to the same slot takes it over, its sums from zero
    hashed = splits.saturation._slots(np.arange(1, 4096, dtype=np.int64), 4)
    other = int(np.arange(1, 4096)[(hashed == slot[0]) & (np.arange(1, 4096) != 5)][0])
    table, got = splits.add(table, np.array([other], np.int64), rgb[2:])
    assert got[0] == slot[0] and table.count[got[0]] == 1 and table.cell[got[0]] == other


def posterior_with(mean, colour):
    """A one-component mixture (only the fields earned_levels reads)."""
    from types import SimpleNamespace
    return SimpleNamespace(origin=np.zeros(3), space=SimpleNamespace(mean=np.asarray(mean)[None]),
                           colour=SimpleNamespace(mean=np.asarray(colour)[None]))


def test_points_seed_children_at_the_levels_whose_cells_earn_one_over_batches():
    """One grey component over a unit square whose left half is red; one point in each
    level-1 cell (half the side), shown batch after batch. A cell's score is the
    ``score`` above at its count: the red cells earn a child at the fourth batch (1.44
    nats), at levels 1 and 2 (each level's cell holds the same point); grey never."""
    rule = grow.Growth(cell=1.0, levels=3, refine=1.0, max_new=100)
    xyz = np.array([[0.25, 0.25, 0.5], [0.25, 0.75, 0.5], [0.75, 0.25, 0.5], [0.75, 0.75, 0.5]])
    red = xyz[:, 0] < 0.5
    rgb = np.where(red[:, None], [0.9, 0.1, 0.1], [0.5, 0.5, 0.5])
    post = posterior_with([0.5, 0.5, 0.5], [0.5, 0.5, 0.5])
    table = splits.no_colours(10)
    earned = []
    for _ in range(4):
        earns, table = splits.earned_levels(rule, post, np.array([True]), xyz, rgb, table,
                                            prior=PriorConfig(), gain=0.0)
        earned.append(earns)
    assert not np.any(earned[:3])
    red_row, none = [False, True, True], [False] * 3
    assert earned[3].tolist() == [red_row, red_row, none, none]
    # no cell finer than the floor of pixel footprints: footprints of 0.6 allow level 1
    # only (side 0.5 >= 0.5 x 0.6 = 0.3 > 0.25)
    earns, _ = splits.earned_levels(rule, post, np.array([True]), xyz, rgb, table,
                                    prior=PriorConfig(), gain=0.0,
                                    footprint=np.full(4, 0.6), floor=0.5)
    assert earns.tolist() == [[False, True, False]] * 2 + [none] * 2


def _bowl_cell(curvature: float, side: int = 5):
    """A parent fitted to a unit patch ``z = curvature (x^2 + y^2)`` (40 x 40 points) and
    one of its level-2 cells (side 0.25, ``side^2`` points), as :func:`splits.
    surface_gain` reads them: the cell's sums about its centre, the parent's mean in that
    frame and its expected covariance (posterior of a prior at cov_scale 0.6, thickness
    0.1, one pseudo-point)."""
    def surface(g):
        x, y = np.meshgrid(g, g)
        return np.stack([x.ravel(), y.ravel(), curvature * (x.ravel()**2 + y.ravel()**2)], 1)

    whole = surface(np.linspace(-0.5, 0.5, 40))
    mu = whole.mean(0)
    cov = (np.diag([1.0, 1.0, 0.01]) * 0.36 + (whole - mu).T @ (whole - mu)) / (len(whole) + 1)
    centre = np.array([0.375, 0.375, 0.0])
    off = surface(np.linspace(0.27, 0.48, side)) - centre
    n = np.array([len(off)], np.float64)
    return n, off.sum(0)[None], np.einsum("pi,pj->ij", off, off)[None], (mu - centre)[None], \
        cov[None]


def test_the_shape_term_is_nothing_on_a_flat_patch_and_pays_where_it_bends():
    """A child of a flat parent's cell explains nothing the parent does not; where the
    surface bends away from the parent's plane the parent misses the points and the
    child gains, the more points the cell has shown the more (measured: 0, 7.16, 18.87,
    19.41 nats at curvature 0, 0.01, 0.05, 0.2 with 25 points: the parent's own spread
    across its plane grows with the bend; 35.3 with 49 at 0.05)."""
    gains = [float(splits.surface_gain(*_bowl_cell(c))[0]) for c in (0.0, 0.01, 0.05, 0.2)]
    np.testing.assert_allclose(gains, [0.0, 7.16, 18.87, 19.41], atol=0.01)
    assert float(splits.surface_gain(*_bowl_cell(0.05, side=7))[0]) > 1.5 * gains[2]


def test_the_table_keeps_the_places_of_a_cell_s_points_when_asked():
    table = splits.no_colours(4, shape=True)
    keys = np.array([5, 5], np.int64)
    rgb = np.full((2, 3), 0.5)
    offsets = np.array([[0.1, 0.0, 0.0], [-0.1, 0.2, 0.0]])
    table, slot = splits.add(table, keys, rgb, offsets)
    table, slot = splits.add(table, keys[:1], rgb[:1], offsets[:1])
    np.testing.assert_allclose(table.place[slot[0]], [0.1, 0.2, 0.0], rtol=1e-6)
    want = 2 * np.outer(offsets[0], offsets[0]) + np.outer(offsets[1], offsets[1])
    np.testing.assert_allclose(table.spread[slot[0]], want, rtol=1e-6, atol=1e-8)
    assert splits.no_colours(4).place is None
