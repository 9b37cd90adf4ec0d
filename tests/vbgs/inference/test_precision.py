"""Right answers whatever the matmul precision: TF32 products emulated on the CPU.

NVIDIA GPUs run float32 products in TF32 by default (10-bit mantissa operands). The
helper :mod:`tf32` (the ``tf32`` fixture) rounds the operands of every default-precision
product that way, so these tests guard on CI what only a GPU would show. The last tests
remove the protection (products at default precision) and show the fit collapsing, so
they fail if the protection is ever lost.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vbgs.baseline import TrainConfig, Trainer, camera_extent, params_from_prior, to_splats
from vbgs.data.images import image_to_points, load_image
from vbgs.data.synthetic import object_scene
from vbgs.inference import model, precision
from vbgs.inference.fit import fit
from vbgs.inference.model import used_components
from vbgs.render.camera import unproject
from vbgs.render.image import render_image
from vbgs.render.metrics import psnr
from vbgs.render.raster import rasterize

SIZE, K, ITERS = 48, 1000, 2


def _fit_image():
    img = load_image("astronaut", SIZE)
    uv, rgb = image_to_points(img)
    prior = model.init(uv, rgb, K, key=jax.random.key(0), scheme="data")
    post, _ = fit(prior, uv, rgb, iters=ITERS)
    used = int(used_components(post.alpha - prior.alpha).sum())
    return psnr(render_image(post, SIZE, SIZE), img), used


@pytest.fixture(scope="module")
def reference_fit():
    return _fit_image()


def test_round_tf32_keeps_ten_mantissa_bits(tf32):
    x = jnp.asarray([1.0, 1.0 + 2**-11, 1.0 + 3 * 2**-11, 1.0 + 2**-10, np.pi, -2.5e-8],
                    jnp.float32)
    out = np.asarray(tf32.round_tf32(x))
    # ties go to even; 1 + 2^-10 is representable; pi -> 3.140625 (= 3217 / 1024)
    np.testing.assert_array_equal(out[:5], np.float32([1.0, 1.0, 1.0 + 2**-9, 1.0 + 2**-10,
                                                       3.140625]))
    assert abs(out[5] / -2.5e-8 - 1) < 2**-11


def test_emulation_changes_default_products_only(tf32):
    a = jnp.asarray(np.random.default_rng(0).normal(size=(8, 8)), jnp.float32)
    with tf32.emulated_tf32():
        default = np.asarray(a @ a)
        highest = np.asarray(precision.matmul(a, a))
    exact = np.asarray(a, np.float64) @ np.asarray(a, np.float64)
    assert np.abs(default - exact).max() > 1e-4  # rounded operands
    assert np.abs(highest - exact).max() < 1e-5


def test_image_fit_unchanged_under_tf32(reference_fit, tf32):
    with tf32.emulated_tf32():
        emulated = _fit_image()
    assert abs(emulated[0] - reference_fit[0]) < 0.1, (emulated, reference_fit)
    assert emulated[1] == reference_fit[1]


def test_image_fit_degrades_without_explicit_precision(reference_fit, monkeypatch, tf32):
    """Products at default precision (the protection removed) collapse under TF32."""
    monkeypatch.setattr(precision, "PRODUCT_PRECISION", jax.lax.Precision.DEFAULT)
    with tf32.emulated_tf32():
        emulated = _fit_image()
    assert emulated[0] < reference_fit[0] - 3.0, (emulated, reference_fit)


@pytest.mark.parametrize("estep", ["dense", "sparse"])
def test_scene_update_unchanged_under_tf32(estep, tf32):
    scene = object_scene(size=24, n_train=2, n_test=1, seed=0)
    xyz, rgb = unproject(scene.train[0].camera, scene.train[0].rgb, scene.train[0].depth)
    prior = model.init(xyz, rgb, 300, key=jax.random.key(0), scheme="data", bounds=scene.bounds)
    ref, ref_info = model.update(model.start(prior), xyz, rgb, estep=estep)
    with tf32.emulated_tf32():
        emu, emu_info = model.update(model.start(prior), xyz, rgb, estep=estep)
    np.testing.assert_allclose(emu.stats.count, ref.stats.count, rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(emu_info.point_loglik, ref_info.point_loglik, rtol=1e-5, atol=1e-3)


# --------------------------------------------------------------------------- 3-D splats


@pytest.fixture(scope="module")
def splat_scene():
    """A 24 px object scene (2 training views) and baseline params from the VBGS data init."""
    scene = object_scene(size=24, n_train=2, n_test=1, seed=0)
    xyz, rgb = (np.concatenate(a) for a in zip(
        *[unproject(f.camera, f.rgb, f.depth) for f in scene.train], strict=True))
    prior = model.init(xyz, rgb, 150, key=jax.random.key(0), scheme="data", bounds=scene.bounds)
    return scene, params_from_prior(prior)


def _render(scene, params):
    """Covariances from scales and rotations, projection and compositing of the test view:
    rgb and depth ``[2, h, w, 3]``."""
    out = rasterize(to_splats(params), scene.test[0].camera, background=scene.background,
                    capacity=256, impl="xla")
    return np.stack([np.asarray(out.rgb), np.asarray(out.depth)[..., None].repeat(3, -1)])


def _baseline_fit(scene, params, steps=6):
    """A few gradient-baseline steps (rasterizer, SSIM loss, Adam): losses and final params."""
    extent = camera_extent([f.camera.position for f in scene.train])
    config = TrainConfig(lr_decay_steps=steps, depth_weight=0.1, raster_capacity=256)
    trainer = Trainer(config, extent=extent)
    state = trainer.init(params, key=jax.random.key(1))
    state, losses = trainer.train(state, scene.train, steps,
                                  jnp.asarray(scene.background, jnp.float32))
    return np.asarray(losses), state.params


def test_render_unchanged_under_tf32(splat_scene, monkeypatch, tf32):
    """Equal under emulated TF32; and the guard bites: with the products at default
    precision (the protection removed) TF32 moves the render."""
    reference = _render(*splat_scene)
    with tf32.emulated_tf32():
        emulated = _render(*splat_scene)
    assert reference[0].max() > 0.3  # the object is in view
    np.testing.assert_allclose(emulated, reference, atol=1e-5)
    monkeypatch.setattr(precision, "PRODUCT_PRECISION", jax.lax.Precision.DEFAULT)
    with tf32.emulated_tf32():
        unprotected = _render(*splat_scene)
    assert np.abs(unprotected - reference).max() > 1e-3


@pytest.mark.skipif(jax.default_backend() != "cpu", reason=(
    "a CPU emulation of a GPU's TF32: on a GPU the products already run so, and Adam "
    "turns its scatter-adds' run-to-run rounding on near-zero rotation gradients into "
    "1e-5 steps (seen on an H200), which this test's 1e-6 cannot tell from TF32"))
def test_baseline_fit_unchanged_under_tf32(splat_scene, tf32):
    ref_losses, ref_params = _baseline_fit(*splat_scene)
    with tf32.emulated_tf32():
        emu_losses, emu_params = _baseline_fit(*splat_scene)
    moved = np.abs(np.asarray(ref_params.means - splat_scene[1].means)).max()
    assert moved > 1e-3, moved  # the steps really change the splats
    np.testing.assert_allclose(emu_losses, ref_losses, rtol=1e-5)
    for name, emu, ref in zip(ref_params._fields, emu_params, ref_params, strict=True):
        np.testing.assert_allclose(emu, ref, rtol=1e-5, atol=1e-6, err_msg=name)


@pytest.mark.parametrize("thin", [1.0, 1e-3, 1e-6])
def test_logdet3_is_slogdets(thin):
    """Elementwise log |det| of 3x3 matrices equals LAPACK's, numpy (float64) and JAX
    (float32) alike, down to components a millionth as thick as they are wide (planar
    data), far from the origin's scale too."""
    rng = np.random.default_rng(0)
    axes = np.linalg.qr(rng.normal(size=(200, 3, 3)))[0]
    spread = np.array([1.0, 0.5, thin])[None] * rng.uniform(0.5, 2.0, (200, 1)) * 40.0
    s = axes @ (spread[:, :, None] * np.swapaxes(axes, 1, 2))
    want = np.linalg.slogdet(s)[1]
    np.testing.assert_allclose(precision.logdet3(s), want, rtol=1e-9, atol=1e-6)
    got = np.asarray(jax.jit(precision.logdet3)(jnp.asarray(s, jnp.float32)))
    # float32: the determinant of a matrix this thin keeps about eps / thin of relative
    # accuracy, as LAPACK's LU in float32 does
    lu = np.asarray(jnp.linalg.slogdet(jnp.asarray(s, jnp.float32))[1])
    np.testing.assert_allclose(got, want, atol=max(1e-4, 3e-7 / thin))
    np.testing.assert_allclose(lu, want, atol=max(1e-4, 3e-7 / thin))


@pytest.mark.parametrize("thin", [1.0, 1e-3, 1e-6])
def test_ldl3_quadratic_forms_hold_for_thin_matrices(thin):
    """``u^T s^-1 v`` through the elementwise LDL^T factors, float32, against float64
    LAPACK, down to matrices a millionth as thick as wide at unit trace (regularised by
    1e-6 I), as the along-ray see-through reads thin surface components: as accurate as
    LAPACK's own float32 inverse, checked alongside (measured, seeds 1-3: 2.7e-7 / 5.1e-5
    / 0.024 relative at the worst, LAPACK 1.7e-7 / 6.0e-5 / 0.028; the conditioning's
    eps / thin)."""
    rng = np.random.default_rng(1)
    axes = np.linalg.qr(rng.normal(size=(500, 3, 3)))[0]
    spread = np.array([1.0, 0.5, thin])[None] * rng.uniform(0.5, 2.0, (500, 1))
    s = axes @ (spread[:, :, None] * np.swapaxes(axes, 1, 2))
    s = s / np.trace(s, axis1=1, axis2=2)[:, None, None] + 1e-6 * np.eye(3)
    u, v = rng.normal(size=(2, 500, 3))
    inv = np.linalg.inv(s)
    want_uu = np.einsum("ki,kij,kj->k", u, inv, u)
    want_uv = np.einsum("ki,kij,kj->k", u, inv, v)

    @jax.jit
    def forms(s, u, v):
        f = precision.ldl3(s)
        yu = precision.unit_lower_solve3(f, *u.T)
        yv = precision.unit_lower_solve3(f, *v.T)
        d = (f.d0, f.d1, f.d2)
        return (sum(a * a / w for a, w in zip(yu, d, strict=True)),
                sum(a * b / w for a, b, w in zip(yu, yv, d, strict=True)))

    uu, uv = (np.asarray(a, np.float64) for a in forms(*(jnp.asarray(a, jnp.float32)
                                                          for a in (s, u, v))))
    tol = {1.0: 1e-6, 1e-3: 2e-4, 1e-6: 4e-2}[thin]
    np.testing.assert_allclose(uu, want_uu, rtol=tol)
    # u^T s^-1 v has no sign of its own: relative to the scale of the forms it mixes
    np.testing.assert_allclose(uv, want_uv, atol=tol * np.sqrt(want_uu * np.einsum(
        "ki,kij,kj->k", v, inv, v)).max())
    lapack = np.asarray(jnp.linalg.inv(jnp.asarray(s, jnp.float32)), np.float64)
    np.testing.assert_allclose(np.einsum("ki,kij,kj->k", u, lapack, u), want_uu, rtol=tol)


def _eigh3(s):
    """:func:`vbgs.inference.precision.eigh3` of ``s [m, 3, 3]`` in float32 (jitted)."""
    upper = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    s = jnp.asarray(s, jnp.float32)
    values, vectors = jax.jit(precision.eigh3)(*(s[:, i, j] for i, j in upper))
    return np.asarray(values, np.float64), np.asarray(vectors, np.float64)


def _angle(a, b):
    """Radians between the lines along ``a [m, 3]`` and ``b [m, 3]`` (by the cross
    product: an arccos of a float32 dot product is off by 3e-4 rad at 0)."""
    cross = np.linalg.norm(np.cross(a, b), axis=1)
    return np.arcsin(np.clip(cross / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1),
                             0.0, 1.0))


@pytest.mark.parametrize("thin", [1.0, 1e-3, 1e-6])
@pytest.mark.parametrize("size", [1e-12, 1.0, 1e12])
def test_eigh3_finds_each_patch_normal_as_float64_lapack(thin, size):
    """Elementwise Jacobi in float32 against float64 LAPACK on the same (float32-rounded)
    matrices: orthonormal vectors, ascending values, the matrix rebuilt to float32's
    rounding of its largest eigenvalue, and the smallest eigenvalue's vector (a patch's
    normal) within float32's rounding of the direction whatever the patch's size, down to
    patches a millionth as thick as wide, and at least as close as XLA's own float32
    ``eigh``."""
    rng = np.random.default_rng(2)
    axes = np.linalg.qr(rng.normal(size=(2000, 3, 3)))[0]
    spread = np.array([thin, 0.5, 1.0])[None] * rng.uniform(0.5, 2.0, (2000, 3)) * size
    s = (axes @ (spread[:, :, None] * np.swapaxes(axes, 1, 2))).astype(np.float32)
    want_values, want_vectors = np.linalg.eigh(s.astype(np.float64))
    values, vectors = _eigh3(s)
    assert (np.diff(values, axis=1) >= 0).all()
    np.testing.assert_allclose(np.swapaxes(vectors, 1, 2) @ vectors,
                               np.broadcast_to(np.eye(3), (2000, 3, 3)), atol=1e-6)
    rebuilt = vectors @ (values[:, :, None] * np.swapaxes(vectors, 1, 2))
    scale = want_values[:, 2][:, None, None]
    assert (np.abs(rebuilt - s) / scale).max() < 1e-6
    np.testing.assert_allclose(values / scale[:, :, 0], want_values / scale[:, :, 0],
                               atol=1e-6)
    normal = _angle(vectors[:, :, 0], want_vectors[:, :, 0])
    xla = _angle(np.asarray(jnp.linalg.eigh(jnp.asarray(s))[1], np.float64)[:, :, 0],
                 want_vectors[:, :, 0])
    # a direction is as well defined as its eigenvalue is apart from the next: float32's
    # rounding of the matrix moves it by about eps * largest / gap
    bound = 1e-6 + 1e-6 * want_values[:, 2] / (want_values[:, 1] - want_values[:, 0])
    assert (normal <= bound).all(), (normal / bound).max()
    assert np.median(normal) <= max(np.median(xla), 1e-7), (np.median(normal),
                                                            np.median(xla))


def test_eigh3_leaves_diagonal_and_isotropic_matrices_as_they_are():
    """A diagonal matrix needs no rotation: its own axes come back, sorted; a multiple
    of the identity (every direction an eigenvector) and the zero matrix (a padded
    patch) come back as the identity, finite."""
    s = np.zeros((3, 3, 3), np.float32)
    s[0] = np.diag([3.0, 1.0, 2.0])
    s[1] = 5.0 * np.eye(3)
    values, vectors = _eigh3(s)
    np.testing.assert_array_equal(values[0], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(np.abs(vectors[0]), np.eye(3)[:, [1, 2, 0]])
    np.testing.assert_array_equal(vectors[1:], np.broadcast_to(np.eye(3), (2, 3, 3)))
    np.testing.assert_array_equal(values[2], [0.0, 0.0, 0.0])


def test_cholesky_solve_is_lapack_solve_on_normal_equations():
    """Elementwise Cholesky solves of 6x6 normal equations (a patch's quadric) in
    float32 against float64 LAPACK: well-conditioned systems to float32's rounding of
    their condition, and a column the patch cannot tell (all zero, the ridge alone on
    its diagonal) solved to 0."""
    rng = np.random.default_rng(3)
    design = rng.normal(size=(1000, 40, 6))
    design[:10, :, 5] = 0.0  # a term these patches cannot tell
    h = rng.normal(size=(1000, 40))
    gram = np.swapaxes(design, 1, 2) @ design
    gram += 1e-6 * np.trace(gram, axis1=1, axis2=2)[:, None, None] * np.eye(6)
    rhs = np.einsum("mkp,mk->mp", design, h)
    want = np.linalg.solve(gram, rhs[..., None])[..., 0]
    entries = {(i, j): jnp.asarray(gram[:, i, j], jnp.float32)
               for i in range(6) for j in range(i, 6)}
    got = np.stack([np.asarray(c, np.float64) for c in jax.jit(precision.cholesky_solve)(
        entries, [jnp.asarray(rhs[:, i], jnp.float32) for i in range(6)])], 1)
    np.testing.assert_allclose(got, want, atol=1e-5 * np.abs(want).max())
    assert np.abs(got[:10, 5]).max() == 0.0
