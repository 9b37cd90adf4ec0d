"""Every reported number: PSNR and SSIM against scikit-image, depth L1 on a known case."""

import numpy as np
import pytest
from skimage import data, transform
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from vbgs.render import metrics


def _pair(height, width, noise, seed=0):
    img = transform.resize(data.astronaut(), (height, width)).astype(np.float32)
    rng = np.random.default_rng(seed)
    noisy = np.clip(img + rng.normal(0, noise, img.shape), 0, 1).astype(np.float32)
    return noisy, img


def _skimage_ssim(a, b, **kw):
    """The 3DGS papers' SSIM in scikit-image's terms: Gaussian window (sigma 1.5,
    11 taps), population covariances, data range 1."""
    return structural_similarity(b, a, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                 use_sample_covariance=False, **kw)


@pytest.mark.parametrize("noise", [0.01, 0.05, 0.2])
def test_psnr_equals_skimage(noise):
    a, b = _pair(48, 40, noise)
    assert metrics.psnr(a, b) == pytest.approx(peak_signal_noise_ratio(b, a, data_range=1.0),
                                               abs=1e-4)


def test_psnr_known_values():
    a = np.zeros((4, 4, 3), np.float32)
    assert metrics.psnr(a, a + 0.1) == pytest.approx(20.0, abs=1e-4)  # MSE 0.01
    assert metrics.psnr(a, a + 0.5, data_range=2.0) == pytest.approx(
        10 * np.log10(4 / 0.25), abs=1e-4)
    assert metrics.psnr(a, a) == float("inf")


@pytest.mark.parametrize("noise", [0.02, 0.1, 0.3])
def test_ssim_equals_skimage_colour_and_grey(noise):
    a, b = _pair(48, 40, noise)
    assert metrics.ssim(a, b) == pytest.approx(_skimage_ssim(a, b, channel_axis=-1), abs=1e-5)
    assert metrics.ssim(a[..., 1], b[..., 1]) == pytest.approx(
        _skimage_ssim(a[..., 1], b[..., 1]), abs=1e-5)


def _naive_ssim(a, b, window):
    """Mean SSIM over every fully inside ``window x window`` position of each channel,
    with a normalised truncated Gaussian (sigma 1.5), k1 = 0.01, k2 = 0.03, range 1."""
    t = np.arange(window) - (window - 1) / 2
    g = np.exp(-0.5 * t**2 / 1.5**2)
    w = np.outer(g, g) / np.outer(g, g).sum()
    c1, c2 = 0.01**2, 0.03**2
    values = []
    for ch in range(a.shape[-1]):
        x, y = a[..., ch].astype(np.float64), b[..., ch].astype(np.float64)
        for i in range(x.shape[0] - window + 1):
            for j in range(x.shape[1] - window + 1):
                px, py = x[i:i + window, j:j + window], y[i:i + window, j:j + window]
                mx, my = (w * px).sum(), (w * py).sum()
                vx, vy = (w * px**2).sum() - mx**2, (w * py**2).sum() - my**2
                cxy = (w * px * py).sum() - mx * my
                values.append((2 * mx * my + c1) * (2 * cxy + c2)
                              / ((mx**2 + my**2 + c1) * (vx + vy + c2)))
    return float(np.mean(values))


def test_ssim_equals_a_naive_window_loop_also_for_small_images():
    a, b = _pair(14, 12, 0.1)
    assert metrics.ssim(a, b) == pytest.approx(_naive_ssim(a, b, 11), abs=1e-5)
    a, b = _pair(9, 10, 0.1)  # 9 px tall: the largest window that fits is 9x9
    assert metrics.ssim_window(9, 10) == 9 and metrics.ssim_window(10, 10) == 9
    assert metrics.ssim(a, b) == pytest.approx(_naive_ssim(a, b, 9), abs=1e-5)


def test_ssim_of_identical_images_is_one_and_refuses_shape_mismatch():
    a, _ = _pair(16, 16, 0.0)
    assert metrics.ssim(a, a) == pytest.approx(1.0, abs=1e-6)
    with pytest.raises(ValueError, match="differ in shape"):
        metrics.ssim(a, a[:8])


def test_depth_l1_skips_invalid_target_pixels():
    target = np.array([[1.0, 2.0, np.nan], [0.0, np.inf, 4.0]])
    pred = np.array([[1.5, 1.0, 9.0], [9.0, 9.0, 4.25]])
    # valid: 1.0, 2.0, 4.0 -> |0.5|, |1.0|, |0.25|
    assert metrics.depth_l1(pred, target) == pytest.approx((0.5 + 1.0 + 0.25) / 3)
    assert np.isnan(metrics.depth_l1(pred, np.zeros_like(target)))
    with pytest.raises(ValueError, match="differ in shape"):
        metrics.depth_l1(pred, target[:1])
