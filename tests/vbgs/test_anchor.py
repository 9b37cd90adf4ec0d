"""The polish's anchor: zero at the posterior's splats, growing away from them as the
posterior's precision says, and the residual carried onto a changed posterior."""

import jax
import jax.numpy as jnp
import numpy as np
import optax

from vbgs.baseline.anchor import anchor_terms, carry, make_anchor, shape_mean_steps
from vbgs.baseline.params import covariances, init_params, trainable
from vbgs.render.splats import rotations_from_quaternions


def base_params(seed=0, n=5):
    rng = np.random.default_rng(seed)
    params = init_params(rng.normal(size=(n, 3)), rng.uniform(0.2, 0.8, (n, 3)),
                         rng.uniform(0.05, 0.2, (n, 3)))
    quats = rng.normal(size=(n, 4))
    return params._replace(rotations=jnp.asarray(quats / np.linalg.norm(quats, axis=1,
                                                                          keepdims=True),
                                                 jnp.float32))


def anchor_on(base, strength=1.0):
    ones = np.ones(base.capacity)
    return make_anchor(base, mean_strength=strength * ones, dof=strength * ones,
                       colour_precision=strength * ones, opacity_count=strength * ones,
                       points=1.0, weight=1.0)


def test_zero_at_the_base_and_positive_away():
    base = base_params()
    anchor = anchor_on(base)
    np.testing.assert_allclose(anchor_terms(base, anchor), 0.0, atol=2e-5)
    for field, step in (("means", 0.05), ("log_scales", 0.3), ("colour_logits", 0.5),
                        ("opacity_logits", 1.0), ("rotations", 0.3)):
        moved = base._replace(**{field: getattr(base, field) + step})
        terms = np.asarray(anchor_terms(moved, anchor))
        assert (terms > 1e-4).all(), field
        # twice the precision, twice the cost (every term is linear in its precision)
        np.testing.assert_allclose(anchor_terms(moved, anchor_on(base, 2.0)), 2 * terms,
                                   rtol=1e-4)


def test_mean_term_is_the_mahalanobis_distance():
    base = base_params()
    delta = np.array([0.01, -0.02, 0.03], np.float32)
    moved = base._replace(means=base.means + delta)
    cov = np.asarray(covariances(base), np.float64)
    expect = 0.5 * np.einsum("i,kij,j->k", delta, np.linalg.inv(cov), delta)
    only_mean = make_anchor(base, mean_strength=np.ones(5), dof=np.zeros(5),
                            colour_precision=np.zeros(5), opacity_count=np.zeros(5),
                            points=1.0, weight=1.0)
    np.testing.assert_allclose(anchor_terms(moved, only_mean), expect, rtol=1e-3)


def test_carry_keeps_the_residual():
    old, new = base_params(0), base_params(1)
    # an unpolished splat lands on the new base
    carried, changed = carry(old, old, new)
    assert changed.all()
    np.testing.assert_allclose(covariances(carried), covariances(new), atol=1e-6)
    np.testing.assert_allclose(carried.means, new.means, atol=1e-6)
    # a polished one keeps what the polish added
    polished = old._replace(means=old.means + 0.1, colour_logits=old.colour_logits - 0.2)
    carried, _ = carry(polished, old, new)
    np.testing.assert_allclose(carried.means - new.means, 0.1, atol=1e-5)
    np.testing.assert_allclose(carried.colour_logits - new.colour_logits, -0.2, atol=1e-5)
    # rows whose base did not change are left as they are
    same = new._replace(means=new.means.at[0].set(old.means[0]),
                        log_scales=new.log_scales.at[0].set(old.log_scales[0]),
                        rotations=new.rotations.at[0].set(old.rotations[0]),
                        colour_logits=new.colour_logits.at[0].set(old.colour_logits[0]),
                        opacity_logits=new.opacity_logits.at[0].set(old.opacity_logits[0]))
    carried, changed = carry(polished, old, same)
    assert not changed[0] and changed[1:].all()
    np.testing.assert_array_equal(carried.means[0], polished.means[0])


def test_carry_of_a_tilted_flat_splat_stays_its_size():
    """A flat base (thin axis at 1e-6) polished with a 0.05 rad tilt, then the base's thin
    axis widens to 1e-4: the carried disc keeps its size (the linear map of the axes used
    before stretched it to 1.53, five times its 0.3)."""
    base = init_params(np.zeros((1, 3)), np.full((1, 3), 0.5), 0.3)
    flat = base._replace(log_scales=jnp.log(jnp.array([[0.3, 0.3, 1e-6]], jnp.float32)))
    half = 0.025  # a 0.05 rad tilt about x
    tilted = flat._replace(rotations=jnp.array([[np.cos(half), np.sin(half), 0.0, 0.0]],
                                               jnp.float32))
    wider = flat._replace(log_scales=jnp.log(jnp.array([[0.3, 0.3, 1e-4]], jnp.float32)))
    carried, changed = carry(tilted, flat, wider)
    assert changed.all()
    scales = np.sort(np.exp(np.asarray(carried.log_scales[0])))
    np.testing.assert_allclose(scales[1:], 0.3, rtol=0.03)  # the disc keeps its size
    assert scales[0] < 0.3 * 0.05  # and stays thin: at most the tilt's reach
    # the tilt is kept, not undone (0.079 rad: the log-space sum mixes it a little)
    normal = np.linalg.eigh(np.asarray(covariances(carried))[0])[1][:, 0]
    assert 0.04 < np.arccos(abs(normal[2])) < 0.1


def test_a_mean_steps_along_its_splat_s_axes_in_proportion_to_their_scales():
    """A flat splat's mean moves across its surface at the optimiser's rate and along its
    normal (the thin axis) at the ratio of the thin to the wide scale; the other rows and
    fields are the optimiser's own update."""
    base = base_params()
    base = base._replace(log_scales=jnp.log(jnp.asarray([[0.2, 0.1, 0.002]] * 5, jnp.float32)))
    theta = trainable(base)
    axes = np.asarray(rotations_from_quaternions(base.rotations))  # columns: the axes
    grads = jax.tree.map(jnp.ones_like, theta)._replace(
        means=jnp.asarray(axes[:, :, 0] + axes[:, :, 1] + axes[:, :, 2], jnp.float32))
    sgd = optax.sgd(1.0)
    plain, _ = sgd.update(grads, sgd.init(theta), theta)
    shaped, _ = shape_mean_steps(sgd).update(grads, sgd.init(theta), theta)
    along = np.einsum("kai,ka->ki", axes, np.asarray(shaped.means))
    np.testing.assert_allclose(along, np.tile([[-1.0, -0.5, -0.01]], (5, 1)), atol=1e-5)
    for field in ("log_scales", "rotations", "opacity_logits", "colour_logits"):
        np.testing.assert_array_equal(getattr(shaped, field), getattr(plain, field))
