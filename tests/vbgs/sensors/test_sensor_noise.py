"""The axial noise of the active sensors matches its published sigma_z, and the Kinect's
depth comes in the steps of its 1/8 px disparity."""

import numpy as np
import pytest

from vbgs.render.camera import Camera
from vbgs.sensors import SENSORS, kinect_sigma_z, kinect_step, realsense_sigma_z, simulate
from vbgs.sensors.noise import KINECT_BASELINE, KINECT_FOCAL_PX

SIZE = 200  # 40,000 pixels a plane: the std is measured to about 0.4 %


def camera(focal: float = 500.0, size: int = SIZE) -> Camera:
    return Camera(focal, focal, size / 2, size / 2, size, size, np.eye(4))


def errors(name, z, cam, level=1.0, seed=1):
    """Measured minus true depth over the pixels kept, on a plane at ``z`` seen head-on."""
    out = simulate(name, np.full((cam.height, cam.width), z, np.float32), cam, seed=seed,
                   level=level)
    return out[out > 0].astype(np.float64) - z


def test_published_formulas():
    assert kinect_sigma_z(0.4) == pytest.approx(0.0012)
    assert kinect_sigma_z(2.4) == pytest.approx(0.0012 + 0.0019 * 4.0)
    assert kinect_step(1.0) == pytest.approx(1.0 / (8 * 580 * 0.075))  # 2.87 mm
    assert kinect_step(4.0) == pytest.approx(0.04598, rel=1e-3)
    assert realsense_sigma_z(2.0, 500.0) == pytest.approx(4.0 * 0.08 / (500.0 * 0.05))
    cam = camera(250.0)
    assert SENSORS["realsense"].sigma_z(2.0, cam) == pytest.approx(0.0256)
    assert SENSORS["kinect"].sigma_z(2.0, cam, level=2.0) == pytest.approx(2 * kinect_sigma_z(2.0))
    assert np.all(SENSORS["exact"].sigma_z(np.ones(3)) == 0)


@pytest.mark.parametrize("name", ["kinect", "realsense"])
@pytest.mark.parametrize("z", [1.0, 2.0, 4.0])
def test_empirical_std_matches_sigma_z(name, z):
    cam = camera()
    e = errors(name, z, cam)
    sigma = float(SENSORS[name].sigma_z(z, cam))
    # measured: kinect 0.995, 0.959, 0.979 (the 1/8 px rounding of a single depth);
    # realsense 0.994 at each depth (the same normal draws)
    assert e.std() == pytest.approx(sigma, rel=0.10)
    assert abs(e.mean()) < 0.05 * sigma  # no bias
    assert 0.97 < len(e) / SIZE**2 < 0.99  # 2 % random holes, nothing else on a plane


@pytest.mark.parametrize("name", ["kinect", "realsense"])
def test_level_scales_the_std(name):
    cam = camera()
    one, two = errors(name, 2.0, cam).std(), errors(name, 2.0, cam, level=2.0).std()
    assert two / one == pytest.approx(2.0, rel=0.03)
    assert two == pytest.approx(float(SENSORS[name].sigma_z(2.0, cam, level=2.0)), rel=0.10)


def test_realsense_noise_follows_the_frame_focal_length():
    """Half the focal length (half the pixels over the same view): twice the noise."""
    wide, narrow = errors("realsense", 3.0, camera(250.0)), errors("realsense", 3.0, camera())
    assert wide.std() / narrow.std() == pytest.approx(2.0, rel=0.03)
    assert wide.std() == pytest.approx(9 * 0.08 / (250 * 0.05), rel=0.10)  # 5.8 cm


@pytest.mark.parametrize("z", [1.0, 2.0, 4.0])
def test_kinect_depth_comes_in_disparity_steps(z):
    cam = camera()
    out = simulate("kinect", np.full((SIZE, SIZE), z, np.float32), cam, seed=2)
    values = np.unique(out[out > 0].astype(np.float64))
    fb = KINECT_FOCAL_PX * KINECT_BASELINE
    eighths = 8 * fb / values  # disparity in 1/8 px: integers
    assert np.abs(eighths - np.round(eighths)).max() < 1e-3 * z**2
    near = np.abs(values[1:] - z) < 2 * kinect_sigma_z(z)
    steps = np.diff(values)[near]
    assert len(steps) >= 3
    # z^2 / (8 f b) at either end: within the step's own size (1.1 % of z at 4 m) ...
    np.testing.assert_allclose(steps, values[1:][near] ** 2 / (8 * 580 * 0.075),
                               rtol=0.02 * z / 4)
    # ... and exactly z_lo z_hi / (8 f b), the gap between disparities k/8 and (k+1)/8
    exact = (values[:-1] * values[1:])[near] / (8 * fb)
    np.testing.assert_allclose(steps, exact, rtol=1e-4)
    # level 2: 1/4 px steps, twice as coarse
    out2 = simulate("kinect", np.full((SIZE, SIZE), z, np.float32), cam, seed=2, level=2.0)
    quarters = 4 * fb / out2[out2 > 0].astype(np.float64)
    assert np.abs(quarters - np.round(quarters)).max() < 1e-3 * z**2
