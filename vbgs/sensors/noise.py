"""Axial depth noise of active depth sensors: the standard deviations and the Kinect's
disparity quantisation, as plain NumPy functions of z-depth.

Scene units are taken as metres. ``z`` is z-depth (along the optical axis).

* Kinect v1, structured light. Nguyen, Izadi and Lovell, "Modeling Kinect Sensor Noise
  for Improved 3D Reconstruction and Tracking", 3DIMPVT 2012, fitted the axial noise of
  a real Kinect as

      sigma_z(z) = 0.0012 + 0.0019 (z - 0.4)^2  metres  (0.4 m <= z <= 4.5 m).

  The Kinect v1 measures disparity ``d = f b / z`` in steps of 1/8 px, with
  ``f b`` about 580 px * 0.075 m (Khoshelham and Elberink, "Accuracy and Resolution of
  Kinect Depth Data for Indoor Mapping Applications", Sensors 2012), so its depth comes
  in steps of

      dz(z) = z^2 / (8 * 580 * 0.075)  metres  (2.9 mm at 1 m, 46 mm at 4 m).

  ``f`` here is the Kinect's own focal length at its native 640 x 480, not the
  frame's: the step belongs to the sensor, whatever resolution the frame is kept at.
* Active stereo, an Intel RealSense D435-like camera. The depth RMS error of a stereo
  pair (Grunnet-Jepsen, Sweetser and Woodfill, "Best-Known-Methods for Tuning Intel
  RealSense D400 Depth Cameras for Best Performance", Intel white paper) is

      sigma_z(z) = z^2 * subpixel / (f_px * baseline)

  with a baseline of 0.05 m, a subpixel disparity error of 0.08 px and ``f_px`` the
  focal length in pixels of the frame's own camera (a stereo pair matches the pixels
  it has).
"""

from __future__ import annotations

import numpy as np

KINECT_SIGMA_OFFSET = 0.0012  # m: Nguyen et al. 2012, axial noise at the sweet spot
KINECT_SIGMA_CURVE = 0.0019  # m / m^2
KINECT_SIGMA_CENTRE = 0.4  # m
KINECT_FOCAL_PX = 580.0  # Kinect v1 IR camera focal length, px (Khoshelham and Elberink 2012)
KINECT_BASELINE = 0.075  # m, projector to IR camera
KINECT_DISPARITY_STEP = 1.0 / 8.0  # px: disparity is reported in 1/8 px units
KINECT_RANGE = (0.4, 4.5)  # m

REALSENSE_BASELINE = 0.05  # m (D435)
REALSENSE_SUBPIXEL = 0.08  # px, RMS disparity error of the stereo matcher
REALSENSE_RANGE = (0.2, 10.0)  # m


def kinect_sigma_z(z) -> np.ndarray:
    """Kinect v1 axial noise ``0.0012 + 0.0019 (z - 0.4)^2`` m (Nguyen et al. 2012);
    the std of the depth it reports, quantisation included."""
    z = np.asarray(z, np.float64)
    return KINECT_SIGMA_OFFSET + KINECT_SIGMA_CURVE * (z - KINECT_SIGMA_CENTRE) ** 2


def kinect_step(z, level: float = 1.0) -> np.ndarray:
    """Kinect v1 depth step at ``z``: ``z^2 / (8 * 580 * 0.075)`` m, one 1/8 px step of
    disparity; ``level`` scales the disparity step (0: no quantisation)."""
    z = np.asarray(z, np.float64)
    return level * KINECT_DISPARITY_STEP * z**2 / (KINECT_FOCAL_PX * KINECT_BASELINE)


def quantise_disparity(z, level: float = 1.0) -> np.ndarray:
    """Depth ``z`` rounded as a Kinect v1 reports it: disparity ``580 * 0.075 / z`` px
    rounded to ``level / 8`` px and turned back into depth (``level`` 0 returns ``z``).
    A disparity that rounds to 0 (beyond about 700 m) gives depth 0 (no depth)."""
    z = np.asarray(z, np.float64)
    if level == 0:
        return z.copy()
    fb, step = KINECT_FOCAL_PX * KINECT_BASELINE, level * KINECT_DISPARITY_STEP
    with np.errstate(divide="ignore", invalid="ignore"):
        disparity = np.round(fb / z / step) * step
        out = np.where(disparity > 0, fb / disparity, 0.0)
    return np.where(z > 0, out, 0.0)


def realsense_sigma_z(z, focal_px: float, baseline: float = REALSENSE_BASELINE,
                      subpixel: float = REALSENSE_SUBPIXEL) -> np.ndarray:
    """Active stereo axial noise ``z^2 * subpixel / (focal_px * baseline)`` m (Intel's
    D400 tuning paper); ``focal_px`` is the camera's focal length in pixels."""
    if not focal_px > 0:
        raise ValueError(f"focal_px must be positive, got {focal_px!r}")
    z = np.asarray(z, np.float64)
    return z**2 * subpixel / (focal_px * baseline)
