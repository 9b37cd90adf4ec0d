"""vbgs.tracking.register: a frame's pose recovered against a map learned from it and
its neighbours (synthetic room, small size), with and without the sensor's noise."""

import jax
import numpy as np
import pytest

from vbgs import mapping
from vbgs.data.formats import load_scene
from vbgs.mapping.measurement import point_rays
from vbgs.tracking import register, se3


@pytest.fixture(scope="module")
def learned():
    scene = load_scene("room", size=32, n_train=40, n_test=1, seed=0)
    config = mapping.Config(components=1500)
    state = mapping.init(config, key=jax.random.key(0))
    for frame in scene.train[2:7]:  # frame 4 and its neighbours, at their true poses
        state, _ = mapping.update(state, frame, config)
    return register.target(state.mixture.posterior, state.mixture.prior), scene.train[4], state


# One point count at every level: one compilation of the solver (the defaults compile two).
CONFIG = register.TrackConfig(levels=(512, 512), inflate=(1.0, 0.0), passes=(2, 2))


def error(found, true):
    off = se3.relative(true, found)
    return np.linalg.norm(off[:3, 3]), np.degrees(se3.rotation_angle(off[:3, :3]))


def test_recovers_a_small_perturbation(learned):
    target, frame, _ = learned
    true = frame.camera.pose
    # 3 cm and 2 degrees off; the camera's own pose is never read (here: nonsense)
    guess = true @ se3.se3_exp(np.array([0.02, -0.015, 0.01, *np.radians([1.0, -1.5, 0.8])]))
    blind = frame.camera._replace(pose=np.full((4, 4), np.nan))
    found = register.register(target, blind, frame.depth, guess, CONFIG, rgb=frame.rgb)
    trans, rot = error(found.pose, true)
    # measured 0.06 mm, 0.002 degrees (the issue asks < 1 mm, 0.05 degrees)
    print(f"exact depth: {trans * 1e3:.3f} mm, {rot:.4f} degrees")
    assert trans < 1e-3 and rot < 0.05
    assert found.inliers > 0.9
    # the Laplace sigmas: finite and small (measured 0.3-1.1 mm, 0.013-0.021 degrees)
    assert np.all(np.isfinite(found.sigma_t)) and np.all(found.sigma_t < 3e-3)
    assert np.all(found.sigma_r_deg < 0.1)
    # with the depth noise of a Kinect added to the components along each ray
    ray = point_rays(frame.camera._replace(pose=np.eye(4)), frame.depth, "kinect")
    noisy = register.register(target, frame.camera, frame.depth, guess, CONFIG, rgb=frame.rgb,
                              ray=ray)
    trans, rot = error(noisy.pose, true)
    print(f"kinect noise: {trans * 1e3:.3f} mm, {rot:.4f} degrees")
    assert trans < 2e-3 and rot < 0.1
    assert np.all(noisy.sigma_t > found.sigma_t)  # less sure when the depth is noisy


def test_refuses_bad_input(learned):
    target, frame, _ = learned
    with pytest.raises(ValueError, match="at least 6"):
        register.register(target, frame.camera, np.zeros_like(frame.depth), np.eye(4))
    with pytest.raises(ValueError, match="one inflate factor"):
        register.TrackConfig(levels=(100,), inflate=(1.0, 0.0), passes=(1,))


def test_map_table_constant_is_the_e_steps(learned):
    """The table's constant (its log |Psi| elementwise, vbgs.inference.precision.logdet3)
    is the E-step's (vbgs.inference.model.component_terms, LAPACK's slogdet)."""
    from vbgs.inference import model

    *_, state = learned
    posterior = state.mixture.posterior
    used = register.target(posterior, state.mixture.prior).used
    const = np.asarray(register._map_table(posterior))[9, used]
    want = np.asarray(model.component_terms(posterior, None).const)[used]
    np.testing.assert_allclose(const, want, rtol=1e-5, atol=1e-4)
