"""One real RGB-D frame from scikit-image's bundled Middlebury stereo pair.

``skimage.data.stereo_motorcycle()`` returns the left image ``[500, 741, 3]``
uint8, the right image, and a ground-truth disparity ``[500, 741]`` float32.
They are the Middlebury 2014 "Motorcycle" scene downsampled by 4 with
``downscale_local_mean``; the full-resolution calibration (calib.txt:
f = 3979.911 px, cx0 = 1244.772, cx1 = 1369.115, cy = 1019.507, baseline
193.001 mm, doffs = cx1 - cx0 = 124.343 px) divided by 4 gives the values
skimage documents for the shipped size: f = 994.978 px, cx = 311.193 px,
cy = 254.877 px, doffs = 31.086 px, baseline 193.001 mm.

Units checked on the data: disparities span 7.2 to 59.9 px (a quarter of the
full-size values, as expected after downsampling by 4), and a left pixel (row, col) matches the
right pixel (row, col - disp) (mean absolute intensity difference about 8 against
about 31-38 for disp/2 or 2*disp), so disparity is in pixels of the shipped size,
left minus right. Missing ground truth is stored as +inf (the skimage docstring
says NaN; both are handled).

Because the two rectified cameras have different principal points, Middlebury's
depth is ``Z = f * B / (d + doffs)``: ``d + doffs`` is the disparity the two
cameras would show with a shared principal point, which is what the textbook
``f * B / disparity`` assumes. Depth is returned in metres (B = 0.193001 m) and
comes out between 2.11 m (motorcycle front) and 5.02 m (back wall), median 2.75 m;
93% of pixels have depth.

Middlebury principal points count pixel centres at integer coordinates; the
library puts centres at ``col + 0.5`` (:mod:`vbgs.render.camera`), so 0.5 is added.
The pose is the identity: the left camera defines the world frame.

:func:`motorcycle_scene` wraps the frame as a one-view :class:`Scene` named
``motorcycle``, loadable by name (:func:`vbgs.data.formats.load_scene`): the
renderer's oracle check on real RGB-D data is
``python -m experiments.run oracle --scene motorcycle``. With a single view it has
no held-out test views, so learners cannot be scored on it.
"""

from __future__ import annotations

import numpy as np
from skimage import data as skdata

from vbgs.data.scene import Frame, Scene, bounds_from_frames, resize_frame
from vbgs.render.camera import Camera
from vbgs.render.pixels import pixel_centre

MOTORCYCLE_FOCAL = 994.978  # px, at the shipped 741 x 500 size
MOTORCYCLE_CX = 311.193  # px, left camera, integer-centred pixels
MOTORCYCLE_CY = 254.877  # px
MOTORCYCLE_DOFFS = 31.086  # px, cx_right - cx_left
MOTORCYCLE_BASELINE = 0.193001  # metres


def disparity_to_depth(
    disp: np.ndarray, focal: float, baseline: float, doffs: float = 0.0
) -> np.ndarray:
    """Z-depth ``f * baseline / (disp + doffs)`` ``[h, w]`` float32, 0 where disparity is unusable.

    Unusable: NaN, inf, or ``disp + doffs <= 0`` (no finite positive depth).
    """
    disp = np.asarray(disp, np.float64)
    shifted = disp + doffs
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(shifted) & (shifted > 0)
    depth = np.where(ok, focal * baseline / np.where(ok, shifted, 1.0), 0.0)
    return depth.astype(np.float32)


def stereo_motorcycle_frame() -> Frame:
    """The Middlebury Motorcycle left view as an RGB-D :class:`Frame` (depth in metres)."""
    left, _, disp = skdata.stereo_motorcycle()
    height, width = disp.shape
    camera = Camera(
        MOTORCYCLE_FOCAL,
        MOTORCYCLE_FOCAL,
        pixel_centre(MOTORCYCLE_CX),
        pixel_centre(MOTORCYCLE_CY),
        int(width),
        int(height),
        np.eye(4),
    )
    depth = disparity_to_depth(disp, MOTORCYCLE_FOCAL, MOTORCYCLE_BASELINE, MOTORCYCLE_DOFFS)
    return Frame((left[..., :3] / 255.0).astype(np.float32), depth, camera)


def motorcycle_scene(size=None) -> Scene:
    """The motorcycle frame as a one-view scene: ``train`` holds the frame (resized to
    ``size``, see :func:`vbgs.data.scene.target_size`), ``test`` and ``val`` are empty."""
    frame = stereo_motorcycle_frame()
    if size is not None:
        frame = resize_frame(frame, size)
    return Scene("motorcycle", [frame], [], bounds_from_frames([frame]))


REAL_SCENES = {"motorcycle": motorcycle_scene}  # real frames loadable by name
