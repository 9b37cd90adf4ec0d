"""Fixtures shared by the library's tests."""

import pytest

from vbgs.data.images import image_to_points, load_image


@pytest.fixture(scope="session")
def astronaut64():
    """The 64 px astronaut photo ``[64, 64, 3]`` and its pixels as points (``uv [n, 2]``,
    ``rgb [n, 3]``)."""
    img = load_image("astronaut", 64)
    return (img,) + image_to_points(img)
