"""Images as point clouds: bundled photos, pixels <-> (u, v, r, g, b) rows, patch streams.

Pixel ``(row, col)`` becomes the point ``(u, v) = (col + 0.5, row + 0.5)`` (the pixel
centre, as in :mod:`vbgs.render.camera`) with its colour in [0, 1].
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from skimage import data as skdata

from vbgs.data.streams import stream_order
from vbgs.io_atomic import write_atomic
from vbgs.render.pixels import pixel_centres

# Photos shipped inside scikit-image (no download needed).
BUNDLED = (
    "astronaut", "coffee", "chelsea", "cat", "rocket", "camera", "coins", "moon", "text",
    "page", "clock", "hubble_deep_field", "immunohistochemistry", "logo", "colorwheel",
    "retina", "brick", "grass", "gravel", "checkerboard",
)


def as_rgb(image, *, source: str = "image", background=None) -> np.ndarray:
    """Validate and convert an image to float32 RGB ``[h, w, 3]`` in [0, 1].

    Accepts grey ``[h, w]``, ``[h, w, 1]``, grey + alpha ``[h, w, 2]``, RGB or RGBA;
    integers are scaled by their dtype's maximum, floats must already lie in [0, 1].
    Alpha ``a`` is dropped when ``background`` is None, else composited:
    ``rgb = a * rgb + (1 - a) * background``.
    """
    img = np.asarray(image)
    if img.dtype == bool:
        img = img.astype(np.float32)
    if img.ndim == 3 and img.shape[2] in (1, 2):  # grey, grey + alpha
        img = np.concatenate([np.repeat(img[..., :1], 3, axis=2), img[..., 1:]], axis=2)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ValueError(
            f"{source}: expected an image of shape [h, w] or [h, w, C] with C = 1 (grey), "
            f"2 (grey + alpha), 3 (RGB) or 4 (RGBA), got {img.shape}"
        )
    if img.shape[0] == 0 or img.shape[1] == 0:
        raise ValueError(f"{source}: image is empty (shape {img.shape})")
    if np.issubdtype(img.dtype, np.integer):
        img = img.astype(np.float64) / np.iinfo(img.dtype).max
    elif not np.issubdtype(img.dtype, np.floating):
        raise TypeError(f"{source}: pixels must be integers or floats, got dtype {img.dtype}")
    bad = ~np.isfinite(img)
    if bad.any():
        raise ValueError(f"{source}: {int(bad.sum())} pixel values are NaN or inf; clean the image first")
    if img.min() < 0 or img.max() > 1:
        raise ValueError(
            f"{source}: float pixels must lie in [0, 1], got [{img.min():.3g}, {img.max():.3g}]; "
            "divide by 255 for 8-bit data"
        )
    if img.shape[2] == 4 and background is not None:
        alpha = img[..., 3:].astype(np.float64)  # [h, w, 1]
        bg = np.broadcast_to(np.asarray(background, np.float64), (3,))
        img = np.clip(img[..., :3] * alpha + bg * (1.0 - alpha), 0.0, 1.0)
    return img[..., :3].astype(np.float32)


def read_rgb(path: str | Path, *, background=None) -> np.ndarray:
    """An image file as float32 RGB ``[h, w, 3]`` in [0, 1]: the one image reader.

    :func:`read_image_file` decodes, :func:`as_rgb` converts (alpha dropped, or
    composited onto ``background``). A missing file raises ``FileNotFoundError``,
    an undecodable or unusable one ``ValueError``, each naming the file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"image not found: {path}")
    return as_rgb(read_image_file(path), source=str(path), background=background)


def read_image_file(path: str | Path) -> np.ndarray:
    """The pixels of an image file as stored (dtype and channels untouched).

    A file that does not decode (truncated, not an image, unsupported) raises
    ``ValueError`` naming the file, whatever the decoder raised.
    """
    from skimage import io as skio  # imageio and its plugins: imported only for files

    path = Path(path)
    try:
        upright = _exif_upright(path)
        if upright is not None:
            return upright
        with warnings.catch_warnings():  # imageio's plugin notes on a bad file
            warnings.simplefilter("ignore", DeprecationWarning)
            return np.asarray(skio.imread(path))
    except Exception as err:  # PIL/imageio raise OSError, SyntaxError, ValueError, ...
        raise ValueError(
            f"could not read image file {path} ({err}); it may be truncated or not an image: "
            "replace or re-export it"
        ) from err


_EXIF_ORIENTATION = 0x0112  # the EXIF tag; 1 = stored upright
_EXIF_SUFFIXES = (".jpg", ".jpeg", ".png")


def _exif_upright(path: Path) -> np.ndarray | None:
    """The pixels turned upright when a JPEG/PNG's EXIF orientation says the camera was
    held rotated (a phone photo read as stored lies on its side), else None. Needs
    Pillow (it comes with matplotlib); without it the pixels are read as stored."""
    if path.suffix.lower() not in _EXIF_SUFFIXES:
        return None
    try:
        from PIL import Image, ImageOps
    except ImportError:
        return None
    with Image.open(path) as image:
        if image.getexif().get(_EXIF_ORIENTATION, 1) in (0, 1):
            return None
        return np.asarray(ImageOps.exif_transpose(image))


def load_image(name_or_path: str | Path, size: int | tuple[int, int] | None = None, *,
               cache: str | Path | None = None) -> np.ndarray:
    """A bundled photo by name (see ``BUNDLED``) or an image file by path, as float32
    RGB ``[h, w, 3]`` in [0, 1], optionally resized (anti-aliased) to ``size`` (an int
    for a square, or ``(height, width)``).

    ``cache``: a folder that keeps bundled photos at the sizes asked (``.npy``, named
    with the scikit-image and SciPy versions that resized them); a later call reads the
    same pixels back instead of decoding and resizing, and so skips importing
    scikit-image's transform and SciPy (0.3 s of a command's start-up). Image files
    are never cached (they may change)."""
    name = str(name_or_path)
    shape = None
    if size is not None:
        h, w = (size, size) if isinstance(size, (int, np.integer)) else tuple(size)
        if h < 1 or w < 1:
            raise ValueError(f"image size must be positive, got {size!r}")
        shape = (h, w)
    if name in BUNDLED and shape is not None and cache is not None:
        return _cached_photo(name, shape, Path(cache))
    if name in BUNDLED:
        img = _bundled(name)
    else:
        path = Path(name).expanduser()
        if not path.is_file():
            raise FileNotFoundError(
                f"image {name!r} is neither a bundled photo ({', '.join(BUNDLED)}) nor an "
                "existing file"
            )
        img = read_rgb(path)
    return img if shape is None else _resize(img, shape)


def _bundled(name: str) -> np.ndarray:
    return as_rgb(getattr(skdata, name)(), source=name)


def _resize(img: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    from skimage.transform import resize  # with SciPy's ndimage and spatial: 0.3 s

    return np.clip(resize(img, shape, anti_aliasing=True, order=1), 0, 1).astype(np.float32)


def _cached_photo(name: str, shape: tuple[int, int], folder: Path) -> np.ndarray:
    """The bundled photo ``name`` resized to ``shape``, from ``folder`` when there (else
    made and stored): bit for bit what :func:`load_image` makes without a cache."""
    import scipy
    import skimage

    path = folder / f"{name}-{shape[0]}x{shape[1]}-skimage{skimage.__version__}" \
                    f"-scipy{scipy.__version__}.npy"
    try:
        img = np.load(path)
        if img.dtype == np.float32 and img.shape == (*shape, 3):
            return img
    except (OSError, ValueError, EOFError):  # missing, or not a whole .npy: made again
        pass
    img = _resize(_bundled(name), shape)
    try:
        write_atomic(path, lambda tmp: np.save(tmp, img))
    except OSError:  # a read-only cache: the photo is made each time
        pass
    return img


def image_to_points(image) -> tuple[np.ndarray, np.ndarray]:
    """Image ``[h, w, 3]`` -> positions ``uv [h*w, 2]`` and colours ``rgb [h*w, 3]``."""
    img = as_rgb(image)
    h, w, _ = img.shape
    return pixel_centres(h, w), img.reshape(-1, 3)


def patch_stream(
    image, patch: int = 8, order: str = "sequential", *, seed: int = 0
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield ``(uv [m, 2], rgb [m, 3])`` for each ``patch x patch`` tile of the image.

    Tiles are in raster order for ``sequential`` (see :func:`stream_order`); edge tiles
    of an image whose size is not a multiple of ``patch`` are smaller. Together the
    tiles hold every pixel exactly once.
    """
    if not isinstance(patch, (int, np.integer)) or patch < 1:
        raise ValueError(f"patch size must be a positive integer, got {patch!r}")
    img = as_rgb(image)
    h, w, _ = img.shape
    uv = pixel_centres(h, w).reshape(h, w, 2)
    tiles = [(r, c) for r in range(0, h, patch) for c in range(0, w, patch)]
    for i in stream_order(len(tiles), order, seed=seed):
        r, c = tiles[i]
        yield uv[r : r + patch, c : c + patch].reshape(-1, 2), img[r : r + patch, c : c + patch].reshape(-1, 3)
