"""The slow, obvious splat renderer that :func:`vbgs.render.raster.rasterize` is held to.

Written apart from the fast path on purpose: NumPy in float64, its own projection
from the equations, one pixel against every splat, a plain running product for the
transmittance, no tiles, no chunks, no floors. It shares only the *specification*
with :mod:`vbgs.render.raster`: the constants (near plane, clamp and cull bands, footprint
bound, blur, alpha limits) and the output type. So a slip in the fast projection
(a wrong sign in the Jacobian, a clamp on the wrong side, a cull that lets a
splat through) shows up as a difference between the two.

For a splat with world mean μ, covariance Σ, colour c and opacity o seen by a
camera with camera-to-world pose ``[R | C]`` and intrinsics fx, fy, cx, cy:

1. camera coordinates ``t = Rᵀ (μ - C)``; culled unless ``t_z > near`` and
   ``t_z² > NEAR_SIGMAS² tr Σ``;
2. tangents ``τ = (t_x / t_z, t_y / t_z)``; culled unless, per axis,
   ``FRUSTUM_CULL · lo <= τ <= FRUSTUM_CULL · hi`` with ``lo = -c / f``,
   ``hi = (size - c) / f``;
3. image mean ``u = fx τ_x + cx``, ``v = fy τ_y + cy``;
4. Jacobian at the clamped tangents ``τ' = clip(τ, FRUSTUM_CLAMP · lo, FRUSTUM_CLAMP · hi)``:
   ``J = [[fx/t_z, 0, -fx τ'_x / t_z], [0, fy/t_z, -fy τ'_y / t_z]]``;
5. ``Σ' = J Rᵀ Σ R Jᵀ + blur · I``; culled if ``max(Σ'_uu, Σ'_vv) > (MAX_FOOTPRINT · max(w, h))²``
   or ``o < ALPHA_MIN``;
6. at pixel centre p: ``α = min(ALPHA_MAX, o exp(-½ dᵀ Σ'⁻¹ d))``, ``d = p - (u, v)``,
   and α := 0 where ``α < ALPHA_MIN``;
7. splats in increasing t_z: ``C = Σ c_i α_i T_i``, ``D = Σ t_z,i α_i T_i``,
   ``T_i = Π_{j<i} (1 - α_j)``; ``rgb = C + T_final · background``, ``alpha = 1 - T_final``.

Memory and time are O(h · w · k): for tests only.
"""

from __future__ import annotations

import numpy as np

from vbgs.render.camera import Camera, pixel_grid
from vbgs.render.raster import (
    ALPHA_MAX,
    ALPHA_MIN,
    BLUR_VARIANCE,
    FRUSTUM_CLAMP,
    FRUSTUM_CULL,
    MAX_FOOTPRINT,
    NEAR,
    NEAR_SIGMAS,
    RenderOutput,
)
from vbgs.render.splats import Splats


def project_reference(splats: Splats, camera: Camera, near: float = NEAR,
                      blur: float = BLUR_VARIANCE):
    """Steps 1-5 of the module docstring, one splat at a time.

    Returns ``(keep [k] bool, uv [k, 2], cov2 [k, 2, 2], depth [k])`` in float64.
    """
    means, covs = np.asarray(splats.means, np.float64), np.asarray(splats.covs, np.float64)
    opacities = np.asarray(splats.opacities, np.float64)
    pose = np.asarray(camera.pose, np.float64)
    rot, centre = pose[:3, :3], pose[:3, 3]
    focal = np.array([camera.fx, camera.fy], np.float64)
    principal = np.array([camera.cx, camera.cy], np.float64)
    size = np.array([camera.width, camera.height], np.float64)
    lo, hi = -principal / focal, (size - principal) / focal
    k = means.shape[0]
    keep = np.zeros(k, bool)
    uv, cov2, depth = np.zeros((k, 2)), np.tile(np.eye(2), (k, 1, 1)), np.zeros(k)
    for i in range(k):
        t = rot.T @ (means[i] - centre)
        depth[i] = t[2]
        if not (t[2] > near and t[2] ** 2 > NEAR_SIGMAS**2 * np.trace(covs[i])):
            continue
        tangent = t[:2] / t[2]
        if np.any(tangent < FRUSTUM_CULL * lo) or np.any(tangent > FRUSTUM_CULL * hi):
            continue
        uv[i] = focal * tangent + principal
        clamped = np.clip(tangent, FRUSTUM_CLAMP * lo, FRUSTUM_CLAMP * hi)
        jac = np.array([[focal[0] / t[2], 0.0, -focal[0] * clamped[0] / t[2]],
                        [0.0, focal[1] / t[2], -focal[1] * clamped[1] / t[2]]])
        cov2[i] = jac @ rot.T @ covs[i] @ rot @ jac.T + blur * np.eye(2)
        too_wide = max(cov2[i, 0, 0], cov2[i, 1, 1]) > (MAX_FOOTPRINT * size.max()) ** 2
        keep[i] = not too_wide and opacities[i] >= ALPHA_MIN
    return keep, uv, cov2, depth


def render_reference(splats: Splats, camera: Camera, *, background=(0.0, 0.0, 0.0),
                     near: float = NEAR, blur: float = BLUR_VARIANCE) -> RenderOutput:
    """Render every pixel against every splat (module docstring); NumPy float64 arrays."""
    keep, uv, cov2, depth = project_reference(splats, camera, near, blur)
    colours = np.asarray(splats.colours, np.float64)
    opacities = np.asarray(splats.opacities, np.float64)
    background = np.broadcast_to(np.asarray(background, np.float64), (3,))
    h, w = int(camera.height), int(camera.width)
    u, v = pixel_grid(camera)  # [h, w] each
    trans, rgb, dep = np.ones((h, w)), np.zeros((h, w, 3)), np.zeros((h, w))
    for i in sorted(np.flatnonzero(keep), key=lambda i: depth[i]):
        d = np.stack([u - uv[i, 0], v - uv[i, 1]], -1)  # [h, w, 2]
        mahalanobis = np.einsum("hwi,ij,hwj->hw", d, np.linalg.inv(cov2[i]), d)
        alpha = np.minimum(ALPHA_MAX, opacities[i] * np.exp(-0.5 * mahalanobis))
        alpha = np.where(alpha >= ALPHA_MIN, alpha, 0.0)
        rgb += (alpha * trans)[..., None] * colours[i]
        dep += alpha * trans * depth[i]
        trans = trans * (1.0 - alpha)
    return RenderOutput(rgb + trans[..., None] * background, dep, 1.0 - trans, np.zeros((), np.int32))
