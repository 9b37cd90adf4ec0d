"""Opacity from evidence: rays that end on a component against rays that pass through it."""

import jax.numpy as jnp
import numpy as np

from vbgs.render import opacity
from vbgs.render.camera import from_fov


def toy():
    """Three small components on the optical axis of a camera facing a wall at z = 2:
    one on the wall, one floating in front of it, one hidden behind it; and a fourth
    beside the wall where the camera sees sky (no depth)."""
    cam = from_fov(32, 32, np.deg2rad(60), np.eye(4))
    depth = np.full((32, 32), 2.0)
    depth[:, 24:] = 0.0  # sky on the right
    means = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 1.0], [0.0, 0.0, 3.0], [0.8, 0.0, 2.0]])
    covs = np.tile(0.02**2 * np.eye(3), (4, 1, 1))
    return cam, depth, means, covs


def test_hits_passes_and_occlusion():
    cam, depth, means, covs = toy()
    ev = opacity.observe(opacity.no_evidence(4), means, covs, cam, depth)
    hits, passes = np.asarray(ev.hits), np.asarray(ev.passes)
    assert hits[0] > 0 and passes[0] == 0  # on the surface
    assert hits[1] == 0 and passes[1] > 0  # floating in front of it
    assert hits[2] == 0 and passes[2] == 0  # occluded: no evidence either way
    assert hits[3] == 0 and passes[3] > 0  # in front of the sky
    # The counts are rays: the footprint area in pixels, whatever the distance.
    area = 2 * np.pi * ((cam.fx * 0.02 / 2.0) ** 2 + 0.3)  # isotropic: 2π det(Σ')^½
    np.testing.assert_allclose(hits[0], area, rtol=1e-4)
    o = np.asarray(opacity.expected_opacity(ev))
    np.testing.assert_allclose(o[0], (1 + area) / (2 + area), rtol=1e-5)  # Beta(1 + h, 1)
    np.testing.assert_allclose(o[1], 1 / (2 + passes[1]), rtol=1e-5)  # Beta(1, 1 + m)
    assert o[2] == 0.5  # the Beta(1, 1) prior mean
    # Ten such frames: the wall's component is nearly opaque, the floating one nearly clear.
    for _ in range(9):
        ev = opacity.observe(ev, means, covs, cam, depth)
    o = np.asarray(opacity.expected_opacity(ev))
    assert o[0] > 0.95 and o[1] < 0.05 and o[3] < 0.05


def test_evidence_adds_up_in_any_order():
    cam, depth, means, covs = toy()
    rng = np.random.default_rng(0)
    frames = []
    for _ in range(4):
        pose = np.eye(4)
        pose[:3, 3] = rng.uniform(-0.2, 0.2, 3)
        frames.append((cam._replace(pose=pose), depth + rng.uniform(-0.05, 0.05)))
    forward, backward = opacity.no_evidence(4), opacity.no_evidence(4)
    for c, d in frames:
        forward = opacity.observe(forward, means, covs, c, d)
    for c, d in frames[::-1]:
        backward = opacity.observe(backward, means, covs, c, d)
    np.testing.assert_allclose(forward.hits, backward.hits, rtol=1e-6)
    np.testing.assert_allclose(forward.passes, backward.passes, rtol=1e-6)


def test_components_behind_the_camera_or_the_near_plane_get_nothing():
    cam, depth, _, _ = toy()
    means = jnp.asarray([[0.0, 0.0, -1.0], [0.0, 0.0, 0.1]])  # z 0.1 < sqrt(tr cov) = 0.17
    ev = opacity.observe(opacity.no_evidence(2), means, jnp.tile(0.01 * jnp.eye(3), (2, 1, 1)),
                         cam, depth)
    assert float(jnp.max(ev.hits)) == 0.0 and float(jnp.max(ev.passes)) == 0.0


def test_holes_in_a_surface_do_not_lower_opacity():
    """A sensor's hole in the wall (no depth where the wall is) proves nothing: with the
    empty pixels given (the sky only), the wall's component keeps every hit it had and
    gains no pass; read as exact depth (every missing pixel empty) the hole would count
    as rays through the wall."""
    cam, depth, means, covs = toy()
    holed = depth.copy()
    holed[12:20, 12:20] = 0.0  # a hole over the optical axis, where components 0-2 project
    empty = np.zeros_like(depth, bool)
    empty[:, 24:] = True  # what shows nothing: the sky
    exact = opacity.observe(opacity.no_evidence(4), means, covs, cam, depth)
    naive = opacity.observe(opacity.no_evidence(4), means, covs, cam, holed)
    aware = opacity.observe(opacity.no_evidence(4), means, covs, cam, holed, empty=empty)
    o = [np.asarray(opacity.expected_opacity(e)) for e in (exact, naive, aware)]
    assert o[1][0] < 0.3 < 0.7 < o[0][0]  # read as empty space, the hole clears the wall
    assert np.asarray(aware.passes)[0] == 0 and o[2][0] >= 0.5  # no evidence: the prior
    np.testing.assert_allclose(aware.passes[3], exact.passes[3])  # the sky still passes


def test_the_sensor_noise_widens_the_hit_band():
    """A wall measured PASS_SIGMAS + 1 sigma behind a 2 cm thin component: a pass under
    exact depth; a hit when the sensor's own sigma is 5 cm."""
    cam, depth, means, covs = toy()
    far = np.full_like(depth, 2.0 + 0.02 * (opacity.PASS_SIGMAS + 1))
    exact = opacity.observe(opacity.no_evidence(4), means, covs, cam, far)
    noisy = opacity.observe(opacity.no_evidence(4), means, covs, cam, far,
                            sensor_var=np.full(4, 0.05**2))
    assert np.asarray(exact.hits)[0] == 0 and np.asarray(exact.passes)[0] > 0
    assert np.asarray(noisy.hits)[0] > 0 and np.asarray(noisy.passes)[0] == 0


def test_an_indefinite_covariance_gets_no_evidence_and_spoils_no_other():
    """A float32 posterior covariance can come out indefinite (posterior assignment left
    one so on the room); its projection is no ellipse, and its area was inf or NaN."""
    cam, depth, means, covs = toy()
    clean = opacity.observe(opacity.no_evidence(4), means, covs, cam, depth)
    bad = covs.copy()
    bad[1] = np.diag([-0.05, 0.02**2, 0.02**2])  # one negative eigenvalue
    ev = opacity.observe(opacity.no_evidence(4), means, bad, cam, depth)
    hits, passes = np.asarray(ev.hits), np.asarray(ev.passes)
    assert np.isfinite(hits).all() and np.isfinite(passes).all()
    assert hits[1] == 0 and passes[1] == 0
    keep = [0, 2, 3]
    np.testing.assert_array_equal(hits[keep], np.asarray(clean.hits)[keep])
    np.testing.assert_array_equal(passes[keep], np.asarray(clean.passes)[keep])


def test_the_colour_a_frame_shows_at_each_component():
    """The wall's left half is grey, its right half red: each component on the wall gets
    the colour of its half over its five hit samples; one floating in front of the wall
    (no hit) gets none; without the frame's colours none is read, and hits, passes and
    see-throughs are the same either way."""
    cam = from_fov(32, 32, np.deg2rad(60), np.eye(4))
    depth = np.full((32, 32), 2.0)
    rgb = np.full((32, 32, 3), 0.5)
    rgb[:, 16:] = (0.9, 0.1, 0.1)
    means = np.array([[-0.6, 0.0, 2.0], [0.6, 0.0, 2.0], [-0.6, 0.0, 1.0]])
    covs = np.tile(0.02**2 * np.eye(3), (3, 1, 1))
    seen = opacity.frame_evidence(means, covs, cam, depth, rgb=rgb)
    assert np.asarray(seen.n_shown).tolist() == [5, 5, 0]
    np.testing.assert_allclose(np.asarray(seen.shown)[:2], [[0.5] * 3, [0.9, 0.1, 0.1]],
                               rtol=1e-6)
    plain = opacity.frame_evidence(means, covs, cam, depth)
    assert not np.asarray(plain.n_shown).any()
    for a, b in zip(seen[:3], plain[:3], strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_colour_on_reads_only_the_rays_whose_surface_lies_on_the_component():
    """A face tilted 60 degrees to the view, its mean on a wall facing the camera: all
    five samples hit within its (deep) band along the camera axis, but the two to its
    sides reach the wall far off the face's plane, so with ``colour_on`` only the centre
    and the two samples along its untilted axis are read; hits are the same either way."""
    cam = from_fov(32, 32, np.deg2rad(60), np.eye(4))
    depth = np.full((32, 32), 2.0)
    rgb = np.full((32, 32, 3), 0.5)
    tilt = np.deg2rad(60)
    axes = np.array([[np.cos(tilt), 0.0, np.sin(tilt)], [0.0, 1.0, 0.0],
                     [-np.sin(tilt), 0.0, np.cos(tilt)]]).T  # columns: in-plane, in-plane, normal
    covs = (axes @ np.diag([0.3**2, 0.3**2, 0.02**2]) @ axes.T)[None]
    means = np.array([[0.0, 0.0, 2.0]])
    every = opacity.frame_evidence(means, covs, cam, depth, rgb=rgb)
    on = opacity.frame_evidence(means, covs, cam, depth, rgb=rgb, colour_on=True)
    assert int(np.asarray(every.n_shown)[0]) == 5 and int(np.asarray(on.n_shown)[0]) == 3
    np.testing.assert_array_equal(np.asarray(every.hits), np.asarray(on.hits))


def test_the_background_is_seen_through_only_within_the_sensors_range():
    """Under a sensor, a pixel that shows the background (no depth, the sky) proves free
    space for the see-through only where a surface would have returned a depth: the
    component 2 units in front of the sky is seen through with a range of 4.5, not with
    a range of 1.5 (beyond it the sensor returns nothing either), nor when no pixel
    without depth counts (holes); with exact depth (no empty pixels given) it is."""
    cam, depth, means, covs = toy()
    empty = np.zeros_like(depth, bool)
    empty[:, 24:] = True  # the sky

    def through(**kw):
        return np.asarray(opacity.frame_evidence(means, covs, cam, depth, **kw).seen_through)

    assert through()[3]  # exact depth: every pixel without depth is free space
    assert through(empty=empty, through_empty=empty, through_reach=4.5)[3]
    assert not through(empty=empty, through_empty=empty, through_reach=1.5)[3]
    assert not through(empty=empty, through_empty=np.zeros_like(empty))[3]
    assert not through(empty=empty, through_empty=empty, through_reach=4.5)[0]  # on the wall


def test_the_samples_are_summed_in_pairs_to_the_same_totals():
    """The frame's colours are summed over their samples plane by plane, adjacent pairs
    first (``_over_samples``): the same totals as a sum over the samples' axis, for any
    count of samples."""
    from vbgs.render.opacity import _over_samples

    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 5, 8):
        planes = rng.random((n, 64, 3)).astype(np.float32)
        out = np.asarray(_over_samples([jnp.asarray(p) for p in planes]))
        np.testing.assert_allclose(out, planes.sum(0), rtol=1e-6)
    ints = [jnp.full((4,), float(i)) for i in range(5)]
    assert np.asarray(_over_samples(ints)).tolist() == [10.0] * 4
