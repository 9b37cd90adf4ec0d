"""The quadric a measured point is seeded on (vbgs.inference.quadric, grow.seeds_on_patches)."""

import numpy as np

from vbgs.inference import grow, quadric


def _sphere_cap(radius=0.3, n=40, span=0.4):
    """A grid of points on a sphere's cap about +z (radius 0.3 m: the object's scale)."""
    g = np.linspace(-span * radius, span * radius, n)
    a, b = np.meshgrid(g, g)
    z = np.sqrt(radius**2 - a**2 - b**2)
    return np.stack([a.ravel(), b.ravel(), z.ravel()], -1)


def test_a_sphere_without_noise_keeps_its_points_and_radial_normals():
    pts = _sphere_cap()
    chosen = np.arange(0, len(pts), 97)
    normal, height = quadric.quadric_patches(pts, chosen, 48)
    unit = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    radial = pts[chosen] / np.linalg.norm(pts[chosen], axis=1, keepdims=True)
    assert np.abs(np.abs((unit * radial).sum(1)) - 1).max() < 1e-6
    # the quadric passes through the point itself (float32: to a hundredth of a millimetre)
    assert np.abs(height).max() < 1e-5
    # the plane of the first version: its centre lies inside the sphere, off the point
    patch = quadric.patches(pts, chosen, 48)
    off = np.abs(((pts[chosen] - patch.mean(1)) * radial).sum(1))
    assert off.max() > 1e-4


def test_seeds_slide_back_onto_a_noisy_sphere():
    rng = np.random.default_rng(0)
    pts = _sphere_cap(n=60)
    camera = np.array([0.6, 0.0, 1.2])  # an oblique view of the cap
    d = pts - camera
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ray = 0.004 * d  # 4 mm along each ray, about a Kinect's at 1.5 m
    noisy = pts + rng.standard_normal(len(pts))[:, None] * ray
    chosen = np.arange(0, len(pts), 53)
    normals, seeds = grow.seeds_on_patches(noisy, chosen, ray)
    before = np.abs(np.linalg.norm(noisy[chosen], axis=1) - 0.3)
    after = np.abs(np.linalg.norm(seeds, axis=1) - 0.3)
    assert before.mean() > 2.5e-3
    assert after.mean() < 0.3 * before.mean()
    radial = seeds / np.linalg.norm(seeds, axis=1, keepdims=True)
    cosine = np.abs((normals * radial).sum(1))
    assert cosine.mean() > 0.98 and cosine.min() > 0.85


def test_a_ray_in_the_surface_takes_no_step():
    normal = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]])
    steps = quadric.ray_steps(normal, np.array([0.01, 0.01]),
                              np.array([[0.01, 0.0, 0.0], [0.0, 0.0, 0.005]]))
    np.testing.assert_allclose(steps, [0.0, 1.0])


def test_exact_points_under_a_noise_model_stay_on_a_sphere():
    """Depth without noise learned as a Kinect's: the seeds stay on the surface (the
    plane of the first version slid them up to SEED_SIGMAS along their rays)."""
    pts = _sphere_cap(n=60)
    camera = np.array([0.6, 0.0, 1.2])
    d = pts - camera
    ray = 0.004 * d / np.linalg.norm(d, axis=1, keepdims=True)
    chosen = np.arange(0, len(pts), 53)
    _, seeds = grow.seeds_on_patches(pts, chosen, ray)
    assert np.abs(np.linalg.norm(seeds, axis=1) - 0.3).max() < 1e-5


def test_least_squares_is_the_pseudo_inverse_s_solution():
    """The normal equations with their tiny ridge against pinv: the same coefficients on
    patches that tell every term, and 0 (pinv's minimum norm) for a term a patch cannot
    tell (all its points on a line: no spread along b). Float32 normal equations of
    random designs: the coefficients to a few parts in a thousand."""
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(2, 50, 48))
    design = np.stack([np.ones_like(a), a, b, a * a, a * b, b * b], -1)
    h = rng.normal(size=(50, 48))
    want = np.einsum("mpk,mk->mp", np.linalg.pinv(design), h)
    np.testing.assert_allclose(quadric.least_squares(design, h), want, rtol=5e-3, atol=1e-4)
    line = np.stack([np.ones_like(a), a, 0 * b, a * a, 0 * b, 0 * b], -1)
    got = quadric.least_squares(line, h)
    want = np.einsum("mpk,mk->mp", np.linalg.pinv(line), h)
    np.testing.assert_allclose(got, want, rtol=5e-3, atol=1e-4)
    assert not got[:, [2, 4, 5]].any()
