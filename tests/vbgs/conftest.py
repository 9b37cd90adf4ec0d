"""Fixtures shared by the library's tests."""

import importlib.util
from pathlib import Path

import jax
import numpy as np
import pytest

from vbgs.data.images import image_to_points, load_image


@pytest.fixture(scope="session")
def astronaut64():
    """The 64 px astronaut photo ``[64, 64, 3]`` and its pixels as points (``uv [n, 2]``,
    ``rgb [n, 3]``)."""
    img = load_image("astronaut", 64)
    return (img,) + image_to_points(img)


@pytest.fixture(scope="session")
def assert_same():
    """``assert_same(a, b)``: two computations that should agree to the bit. They do on a
    CPU. On a GPU, XLA's scatter-adds and sums use atomics whose order, and so float32
    rounding, changes from run to run (on an H200 the same update run twice differed in
    1e-6 of a mean, and a scatter matrix's small entries, left by cancellation, in 5e-5 of
    its largest): there, equal to that rounding (``rtol`` 1e-5, ``atol`` 1e-4 of the
    array's largest magnitude)."""
    exact = jax.default_backend() == "cpu"

    def check(a, b, err_msg=""):
        a, b = np.asarray(a), np.asarray(b)
        if exact:
            np.testing.assert_array_equal(a, b, err_msg=err_msg)
        else:
            scale = float(np.max(np.abs(b))) if b.size else 0.0
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-4 * scale, err_msg=err_msg)

    return check


@pytest.fixture(scope="session")
def tf32():
    """The helper module ``inference/tf32.py``: ``tf32.emulated_tf32()`` rounds the
    operands of default-precision float32 products as an NVIDIA GPU does by default."""
    spec = importlib.util.spec_from_file_location(
        "tf32", Path(__file__).parent / "inference" / "tf32.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
