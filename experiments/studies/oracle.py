"""The oracle check: does the *renderer* reproduce a scene when the splats are right?

Splats are made directly from one view's ground truth: one small, nearly opaque,
isotropic splat per pixel with valid depth, at the unprojected point, with the
pixel's colour and a world standard deviation of ``ORACLE_SIGMA_PX`` pixels at its
depth (``sigma = ORACLE_SIGMA_PX · z / fx``), rendered without the low-pass dilation
(``blur = 0``) so a splat covers its own pixel and not its neighbours.

* Rendered from the **same view** they must reproduce it (>= 30 dB on the synthetic
  scenes): a lower score means the projection or compositing is wrong.
* Rendered from a **neighbouring view** they must still look right where that view
  sees what the source view saw (``covisible`` pixels: the neighbour's ground-truth
  surface point projects inside the source view and agrees with the source depth
  there within ``COVISIBLE_TOLERANCE`` of the depth). Splats of the source view that
  lie beside or behind the neighbour camera are exactly the ones that near-plane and
  frustum culling and the clamped Jacobian must keep out of the picture.
* Rendered from the source view **together with the oracle splats of frames around
  the trajectory** (``SURROUND``: a quarter, half and three quarters along it), the
  source view must still look right (``psnr_surround``): in a room those splats sit
  beside and behind the camera. A renderer without the Jacobian clamp and frustum
  culling paints them over the whole image (about 10 dB on the room).

So a poor learned scene with a good oracle score is the learner's fault, not the
renderer's. ``python -m experiments.run oracle --scene room`` prints the scores for
any scene (synthetic or a loaded folder).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from vbgs.data.scene import Frame, Scene
from vbgs.render.camera import project, unproject, valid_depth
from vbgs.render.metrics import psnr
from vbgs.render.raster import NEAR, exact_capacity, rasterize, surface_depth
from vbgs.render.splats import Splats

ORACLE_SIGMA_PX = 0.4  # splat standard deviation in pixels of the source view
ORACLE_OPACITY = 0.99  # nearly opaque
COVISIBLE_TOLERANCE = 0.02  # relative depth agreement for a pixel to count as covisible
SURROUND = (0.25, 0.5, 0.75)  # fractions along the trajectory of the surrounding frames


@dataclass(frozen=True)
class OracleScore:
    """Scores of the oracle splats of one source view."""

    view: int  # source training frame
    neighbour: int  # the neighbouring training frame rendered (-1: a one-view scene)
    psnr_same: float  # dB over the whole source view
    psnr_neighbour: float  # dB over the neighbour's covisible pixels (NaN: no neighbour)
    psnr_surround: float  # dB over the source view, with the surrounding frames' splats added
    covisible: float  # fraction of the neighbour's pixels that are covisible (NaN: none)
    depth_l1_same: float  # mean |rendered - true| depth over valid pixels of the source view


def oracle_splats(frame: Frame) -> Splats:
    """One splat per valid-depth pixel of ``frame`` (see the module docstring)."""
    xyz, rgb = unproject(frame.camera, frame.rgb, frame.depth)
    _, z = project(frame.camera, xyz)
    sigma = ORACLE_SIGMA_PX * z / frame.camera.fx  # [n]
    covs = (sigma**2)[:, None, None] * np.eye(3)
    return Splats(jnp.asarray(xyz), jnp.asarray(covs, jnp.float32), jnp.asarray(rgb),
                  jnp.full((len(z),), ORACLE_OPACITY, jnp.float32))


def render_oracle(splats: Splats, frame: Frame, background, near: float = NEAR
                  ) -> tuple[np.ndarray, np.ndarray]:
    """rgb ``[h, w, 3]`` and alpha-normalised depth ``[h, w]`` of the oracle splats, nothing dropped."""
    capacity = exact_capacity(splats, frame.camera, blur=0.0, near=near)
    out = rasterize(splats, frame.camera, background=background, capacity=capacity, blur=0.0,
                    near=near)
    return np.clip(np.asarray(out.rgb), 0.0, 1.0), surface_depth(out)


def covisible_mask(source: Frame, target: Frame) -> np.ndarray:
    """Pixels ``[h, w]`` of ``target`` whose true surface ``source`` also sees."""
    valid = valid_depth(target.depth)
    xyz, _ = unproject(target.camera, target.rgb, target.depth)
    uv, z = project(source.camera, xyz)
    col, row = np.floor(uv).astype(int).T
    inside = (z > 0) & (col >= 0) & (col < source.camera.width) & (row >= 0) & (
        row < source.camera.height)
    seen = np.zeros(len(z), bool)
    d = source.depth[row[inside], col[inside]]
    seen[inside] = valid_depth(d) & (np.abs(d - z[inside]) <= COVISIBLE_TOLERANCE * z[inside])
    mask = np.zeros(valid.shape, bool)
    mask[valid] = seen
    return mask


def masked_psnr(render: np.ndarray, target: np.ndarray, mask: np.ndarray) -> float:
    """PSNR over the pixels in ``mask`` (NaN if none)."""
    if not mask.any():
        return float("nan")
    return psnr(render[mask], target[mask])


def oracle_score(scene: Scene, view: int = 0, neighbour: int | None = None, *,
                 near: float = NEAR) -> OracleScore:
    """Oracle splats of training frame ``view`` against that frame, a neighbour (default
    the next training frame, or the previous one for the last) and the surroundings
    (module docstring); ``near`` is the renderer's near plane. A one-view scene (the
    real motorcycle frame) gets the same-view scores only: NaN for the neighbour, and
    the surround score equals the same-view one (no other frames)."""
    n = len(scene.train)
    if not 0 <= view < n:
        raise ValueError(f"view {view} is not a training frame (the scene has {n})")
    source = scene.train[view]
    splats = oracle_splats(source)
    if splats.count == 0:
        raise ValueError(f"training frame {view} has no valid depth: nothing to build splats from")
    rgb, depth = render_oracle(splats, source, scene.background, near)
    same = psnr(rgb, source.rgb)
    valid = valid_depth(source.depth)
    depth_l1 = float(np.abs(depth - source.depth)[valid].mean())
    if n == 1:
        return OracleScore(view=view, neighbour=-1, psnr_same=same, psnr_neighbour=float("nan"),
                           psnr_surround=same, covisible=float("nan"), depth_l1_same=depth_l1)
    neighbour = (view + 1 if view + 1 < n else view - 1) if neighbour is None else neighbour
    other = scene.train[neighbour]
    rgb_n, _ = render_oracle(splats, other, scene.background, near)
    mask = covisible_mask(source, other)
    around = sorted({(view + int(round(f * n))) % n for f in SURROUND} - {view, neighbour})
    everything = Splats(*(jnp.concatenate(parts) for parts in zip(
        splats, *(oracle_splats(scene.train[i]) for i in around), strict=True)))
    rgb_s, _ = render_oracle(everything, source, scene.background, near)
    return OracleScore(
        view=view, neighbour=neighbour, psnr_same=same,
        psnr_neighbour=masked_psnr(rgb_n, other.rgb, mask), psnr_surround=psnr(rgb_s, source.rgb),
        covisible=float(mask.mean()), depth_l1_same=depth_l1,
    )
