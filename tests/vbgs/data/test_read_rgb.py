"""The one image reader, vbgs.data.images.read_rgb, on small files with known pixels."""

import numpy as np
import pytest
from skimage import io as skio

from vbgs.data.images import load_image, read_rgb


def _save(path, pixels):
    skio.imsave(path, pixels, check_contrast=False)
    return path


def test_rgba_alpha_dropped_or_composited(tmp_path):
    rgba = np.zeros((2, 3, 4), np.uint8)
    rgba[..., 0] = 255  # red
    rgba[..., 3] = [[255, 0, 51], [255, 255, 0]]  # alpha 1, 0, 0.2 / 1, 1, 0
    path = _save(tmp_path / "a.png", rgba)
    np.testing.assert_array_equal(read_rgb(path), np.broadcast_to([1.0, 0.0, 0.0], (2, 3, 3)))
    white = read_rgb(path, background=(1.0, 1.0, 1.0))
    np.testing.assert_allclose(white[0, 1], [1.0, 1.0, 1.0])  # fully transparent -> background
    np.testing.assert_allclose(white[0, 2], [1.0, 0.8, 0.8], atol=1e-6)  # 0.2 red over white
    np.testing.assert_allclose(white[1, 0], [1.0, 0.0, 0.0])


def test_grey_16_bit_and_grey_alpha(tmp_path):
    grey = np.array([[0, 65535], [13107, 32768]], np.uint16)
    got = read_rgb(_save(tmp_path / "g.png", grey))
    assert got.shape == (2, 2, 3) and got.dtype == np.float32
    np.testing.assert_allclose(got[..., 1], grey / 65535.0, atol=1e-7)
    la = np.stack([np.full((2, 2), 102, np.uint8), np.full((2, 2), 255, np.uint8)], -1)  # [h, w, 2]
    np.testing.assert_allclose(read_rgb(_save(tmp_path / "la.png", la)), 0.4, atol=1e-7)


def test_load_image_reads_files_through_the_same_reader(tmp_path):
    pixels = np.arange(2 * 4 * 3, dtype=np.uint8).reshape(2, 4, 3) * 10
    path = _save(tmp_path / "p.png", pixels)
    np.testing.assert_array_equal(load_image(path), read_rgb(path))
    np.testing.assert_allclose(load_image(path)[1, 3], pixels[1, 3] / 255.0, atol=1e-7)


def test_missing_and_bad_files_are_refused_by_name(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.png"):
        read_rgb(tmp_path / "nope.png")
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="bad.png"):
        read_rgb(tmp_path / "bad.png")


def test_a_cached_bundled_photo_is_the_resized_one_to_the_bit(tmp_path, monkeypatch):
    import vbgs.data.images as images

    made = load_image("coffee", (12, 20))
    first = load_image("coffee", (12, 20), cache=tmp_path)  # made and stored
    assert [p.name.split("-")[:2] for p in tmp_path.iterdir()] == [["coffee", "12x20"]]

    def no_resize(*args):
        raise AssertionError("resized again: the cache was not read")

    monkeypatch.setattr(images, "_resize", no_resize)
    again = load_image("coffee", (12, 20), cache=tmp_path)
    for img in (first, again):
        assert img.dtype == np.float32 and img.tobytes() == made.tobytes()


def test_a_broken_cache_entry_is_made_again_and_files_are_never_cached(tmp_path):
    load_image("coffee", 8, cache=tmp_path)
    (entry,) = tmp_path.iterdir()
    for broken in (entry.read_bytes()[:100], b""):  # truncated, empty
        entry.write_bytes(broken)
        assert load_image("coffee", 8, cache=tmp_path).tobytes() == \
            load_image("coffee", 8).tobytes()
    assert np.load(entry).shape == (8, 8, 3)  # stored again, whole
    path = _save(tmp_path / "photo.png", np.zeros((4, 6, 3), np.uint8))
    load_image(path, 2, cache=tmp_path / "files")
    assert not (tmp_path / "files").exists()
