"""Bad input is refused at the boundary with a message that says what is wrong."""

import jax
import numpy as np
import pytest

from vbgs.data.images import as_rgb, image_to_points, load_image, patch_stream
from vbgs.data.streams import stream_order
from vbgs.inference import model


def test_nan_and_inf_pixels():
    img = np.random.default_rng(0).uniform(size=(8, 8, 3)).astype(np.float32)
    img[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        image_to_points(img)
    img[2, 3, 1] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        as_rgb(img)


@pytest.mark.parametrize("shape", [(8,), (8, 8, 6), (8, 8, 5), (2, 8, 8, 3), (0, 4, 3)])
def test_wrong_image_shapes(shape):
    with pytest.raises(ValueError, match="shape|empty"):
        as_rgb(np.zeros(shape, np.float32))


def test_grey_with_alpha_is_read_as_grey_rgb():
    grey_alpha = np.stack([np.full((2, 2), 0.25), np.ones((2, 2))], -1).astype(np.float32)
    np.testing.assert_array_equal(as_rgb(grey_alpha), np.full((2, 2, 3), 0.25, np.float32))


def test_wrong_dtypes_and_ranges():
    with pytest.raises(TypeError, match="dtype"):
        as_rgb(np.zeros((4, 4, 3), np.complex64))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        as_rgb(np.full((4, 4, 3), 255.0))
    assert as_rgb(np.full((4, 4, 3), 255, np.uint8)).max() == 1.0


def test_missing_image_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="neither a bundled photo"):
        load_image(tmp_path / "nope.png")
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    with pytest.raises(ValueError, match="could not read"):
        load_image(bad)


def test_points_and_components_refused():
    uv, rgb = image_to_points(np.zeros((4, 4, 3), np.float32))
    key = jax.random.key(0)
    with pytest.raises(ValueError, match="positive integer"):
        model.init(uv, rgb, 0, key=key)
    with pytest.raises(ValueError, match="init scheme"):
        model.init(uv, rgb, 3, key=key, scheme="kmeans")
    with pytest.raises(ValueError, match=r"\[n, 3\]"):
        model.init(uv, rgb[:, :2], 3, key=key)
    with pytest.raises(TypeError, match="floating point"):
        model.init(uv.astype(np.int32), rgb, 3, key=key)
    bad = uv.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        model.init(bad, rgb, 3, key=key)
    state = model.start(model.init(uv, rgb, 3, key=key))
    with pytest.raises(ValueError, match="3-D but the model is 2-D"):
        model.update(state, np.zeros((4, 3), np.float32), rgb[:4])
    with pytest.raises(ValueError, match="assignment mode"):
        model.update(state, uv, rgb, assign="greedy")
    with pytest.raises(ValueError, match="empty"):
        model.update(state, uv[:0], rgb[:0])
    with pytest.raises(ValueError, match="colour_noise"):
        model.PriorConfig(colour_noise=-1.0)


def test_streams_cover_every_pixel_once_and_refuse_bad_orders():
    img = load_image("coffee", (20, 13))
    seen = np.concatenate([uv for uv, _ in patch_stream(img, 8, "shuffled", seed=2)])
    assert len(seen) == 20 * 13 and len(np.unique(seen, axis=0)) == 20 * 13
    assert stream_order(4, "reversed").tolist() == [3, 2, 1, 0]
    with pytest.raises(ValueError, match="stream order"):
        stream_order(4, "random")
    with pytest.raises(ValueError, match="patch size"):
        next(patch_stream(img, 0))
