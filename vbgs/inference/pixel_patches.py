"""A frame's points' neighbours found on its pixel grid, not in a KD-tree.

A frame's points come from a depth image, so the points nearest a point in 3-D are,
on one surface, those of the pixels about its own pixel. Growth fits each seed's patch
(:mod:`vbgs.inference.quadric`) to such neighbours; a KD-tree over the frame's points
(:func:`vbgs.inference.quadric.neighbour_index`, the reference, which bare point batches
still take) finds them by building a tree of all ~300k points of a 640 x 480 frame for a
few thousand queries. Here they are read off images of the frame instead (:class:`Images`:
each pixel's point index, -1 where it has none, position and noise), gathered on the device
for a chunk of seeds at a time (:func:`chunked`, :func:`nearest`), where the patches are
fitted too (:func:`vbgs.inference.grow.seeds_on_patches`): nothing per seed on the host, so
a GPU takes the whole of it. On this project's 2-core CPU it first cost what numpy's took
(the room at 640 x 480 under the Kinect, 19,833 seeds: 0.43 s either way, some 12 us a
seed); the patch's axes and normal equations now go elementwise
(:func:`vbgs.inference.precision.eigh3`, :func:`~vbgs.inference.precision.cholesky_solve`,
where XLA's batched ``eigh`` and ``solve`` call LAPACK per matrix): 4.3 against 6.0 us a
seed on 8192 seeds of a synthetic 640 x 480 frame (a one-off timing, not kept), of which
gathering the windows and choosing their nearest are now most; the normals are float32's (median
1e-4 rad from numpy's float64, the seeds 6e-8 m; 0.3% of the seeds differ by more than
1e-3 rad, where a bisection's tie at the cut picks another neighbour).

The window is the smallest disc of pixel offsets that holds :data:`WINDOW_SHARE` times
the wanted count (:func:`disc`): 48 neighbours look in the 121 pixels within 6.1 pixels,
12 in the 37 within 3.2; of its points that pass the rule below, the wanted nearest in
3-D are taken, as the KD-tree takes them. Why not the window that holds just the wanted
count (49 pixels within 4 for 48): under a sensor's noise the 48 nearest points in 3-D
spread wider than 4 pixels (a point's neighbours along its ray are far in depth), and
their wider patch tells the normal better. Against the normals and points of the exact
depth (a one-off check: three object frames at 128 px under the Kinect's simulated
noise, 2000 seeds each), the KD-tree's normals were 4.26 degrees off (median; mean
6.97), the 49-pixel window's 5.69 (9.05), the nearest 48 of 121 pixels 4.26 (6.99);
the seeds of the last 0.21 sigma off the surface (median) as the KD-tree's, the
49-pixel window's 0.24. Within 2 or 1.6 times the wanted count the normals were 7.07
and 7.20 degrees off (mean). On a thinned frame (``budget.points``: every s-th pixel) the
offsets step by ``s``.

A window's pixel takes no part when it has no point, or when its point lies farther from
the seed in 3-D than the surface it would share with it allows: a window straddling a
depth edge would mix a foreground and a background surface. The rule: a neighbour ``j``
at pixel offset ``d_j`` (in pixels) is kept when

    |x_j - x_s|^2 <= (FOOTPRINTS * f_s * s * |d_j|)^2 + 2 NOISE_SIGMAS^2 |u_s|^2,

``f_s`` the seed's pixel footprint (depth / focal length, world units), ``u_s`` its
noise along its ray (0 for exact depth; a neighbour's, about as deep, is taken to be
the same). On a surface tilted by ``theta`` from the view a neighbour lies about
``f_s |d_j| / cos(theta)`` away, so :data:`FOOTPRINTS` = 3 keeps surfaces up to 70
degrees from head-on whole; a step in depth of more than some
``3 f_s |d_j|`` (and a few sigma of the noise) is cut. What is left is a masked patch
(``weight [m, k]``, 0 or 1), which the quadric code fits as it fits the KD-tree's (all
weights 1). A window of fewer than ``quadric.PLANE_MIN_POINTS`` kept points (the seed
alone on its surface: a speck, a thin rim) tells no plane: its seed stays at its
measured point with a normal along its viewing ray (:func:`view_normals`).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# A neighbour lies on the seed's surface when it is within this many of the seed's pixel
# footprints per pixel of offset (a surface up to arccos(1/3) = 70 degrees from head-on).
FOOTPRINTS = 3.0
# ... plus this many sigma of the two points' noise along their rays (each the seed's).
NOISE_SIGMAS = 3.0
# The window holds this many times the wanted neighbours, the nearest of which in 3-D
# are taken (module docstring: 1, the window of the wanted count, loses to the KD-tree).
WINDOW_SHARE = 2.5
# Seeds per compiled call of a window's work (:func:`chunked`): one shape a frame size, the
# small one for small frames (a 128 px frame grows hundreds of seeds). A frame's last chunk
# is padded, so a large chunk pays for seeds it does not hold: on ten recorded frames of
# the room at 640 x 480 under the Kinect (2,816 to 24,800 seeds a frame), 1024 took 1.08 s
# for the last nine against 1.34 s at 4096 (the sum of each frame's minimum of 3, load
# 1.3); 512, 1.06 s. By the frame, not the seeds' count: a stream whose count crossed a
# threshold compiled anew mid-stream (2 s).
CHUNK = 1024
SMALL_CHUNK = 512
SMALL_FRAME = 64 * SMALL_CHUNK  # pixels: up to some 180 x 180


class PixelGrid(NamedTuple):
    """Where a frame's points lie on its pixel grid (what :func:`window` reads)."""

    flat: np.ndarray  # [n] int: each point's pixel, row * width + col
    shape: tuple[int, int]  # (height, width) of the image
    step: int  # the lattice the points' pixels lie on (a thinned frame's stride; 1: all)
    footprint: np.ndarray  # [n] each point's pixel footprint (depth / focal, world units)
    eye: np.ndarray  # [3] the camera centre, in the points' coordinates


def disc(wanted: int) -> np.ndarray:
    """``[k, 2]`` int (row, col) offsets: the smallest disc of pixel offsets that holds at
    least ``wanted`` pixels (offset 0 among them), nearest first."""
    r = int(np.ceil(np.sqrt(wanted)))
    span = np.arange(-r, r + 1)
    off = np.stack(np.meshgrid(span, span, indexing="ij"), -1).reshape(-1, 2)
    d2 = (off**2).sum(1)
    order = np.argsort(d2, kind="stable")
    cut = d2[order][min(wanted, len(order)) - 1]  # the wanted-th nearest's distance
    return off[order][d2[order] <= cut]


class Images(NamedTuple):
    """A frame's points as padded images, flat (what :func:`nearest` gathers from):
    ``[P]`` for ``P = (h + 2 pad) (w + 2 pad)``, the pad of -1 / zeros."""

    index: jax.Array  # [P] int32: each pixel's point (-1: none)
    xyz: jax.Array  # [P, 3] float32: its position (0: none)
    noise: jax.Array  # [P, 3] float32: its noise along its ray (0: none, or exact depth)
    width: int  # the padded image's width
    pad: int


def images(x: np.ndarray, grid: PixelGrid, pad: int, ray: np.ndarray | None = None
           ) -> Images:
    """The points ``x [n, 3]`` (and their noise ``ray [n, 3]``) on the pixel grid,
    padded by ``pad`` pixels of nothing so every window reads inside (:class:`Images`).
    The points go up as they are, padded to the most the grid's lattice holds (one shape
    a frame size), and are laid out on the device (:func:`_laid_out`): a 640 x 480
    frame's three padded images are 9 MB, its points on a stride-2 lattice 2 MB."""
    h, w = grid.shape
    width = w + 2 * pad
    size = (h + 2 * pad) * width
    most = -(-h // grid.step) * -(-w // grid.step)  # the lattice's pixels, any offset
    if len(x) > most:
        raise ValueError(f"{len(x)} points do not lie one to a pixel on the {h} x {w} grid's "
                         f"lattice of step {grid.step} ({most} pixels)")
    at = np.full(most, size, np.int32)  # padding: past the end, dropped
    at[:len(x)] = (grid.flat // w + pad) * width + grid.flat % w + pad
    xyz = np.zeros((most, 3), np.float32)
    xyz[:len(x)] = x
    noise = None
    if ray is not None:
        noise = np.zeros((most, 3), np.float32)
        noise[:len(x)] = ray
    return Images(*_laid_out(at, xyz, noise, size), width, pad)


@functools.partial(jax.jit, static_argnames="size")
def _laid_out(at, xyz, noise, size: int):
    """:func:`images`' flat images of ``size`` pixels: each point's index, position and
    noise scattered to its padded pixel ``at [m]`` (``size``: padding, dropped)."""
    index = jnp.full(size, -1, jnp.int32).at[at].set(
        jnp.arange(at.shape[0], dtype=jnp.int32), mode="drop")
    image = jnp.zeros((size, 3), jnp.float32)
    return (index, image.at[at].set(xyz, mode="drop"),
            image if noise is None else image.at[at].set(noise, mode="drop"))


def offsets(wanted: int, grid: PixelGrid) -> tuple[np.ndarray, int]:
    """The window's pixel offsets ``[k, 2]`` (:func:`disc` of :data:`WINDOW_SHARE` times
    ``wanted``, on the grid's lattice) and the pad they need about the image."""
    off = grid.step * disc(max(wanted, int(np.ceil(WINDOW_SHARE * wanted))))
    return off, int(np.abs(off).max())


def nearest(im: Images, at: jax.Array, reach: jax.Array, off: jax.Array, wanted: int
            ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The patches of the points at the padded pixels ``at [m]``, traced: the window's
    pixels ``[m, k]`` (``off [k, 2]`` about each point), the neighbours' offsets from
    the point ``[m, k, 3]`` and weights ``[m, k]``: 1 for the ``wanted`` nearest in 3-D
    of the window's points that the module docstring's rule keeps (``reach [m, k]``: the
    squared distance each offset allows), found by bisection on the distance, ties at
    the cut going to the nearer pixel. The window stays whole, its weights marking the
    patch: compacting it takes a sort, and XLA's sort and top-k cost ten times numpy's
    partition on the CPU, more than fitting the zero-weight rest."""
    pix = at[:, None] + off[:, 0] * im.width + off[:, 1]  # [m, k]
    gap = im.xyz[pix] - im.xyz[at][:, None]
    dist = (gap * gap).sum(-1)  # [m, k]; float32 spares the traffic
    keep = (im.index[pix] >= 0) & (dist <= reach)
    if wanted < off.shape[0]:
        keep = _nearest_kept(dist, keep, wanted)
    return pix, gap, keep.astype(gap.dtype)


def _nearest_kept(dist: jax.Array, keep: jax.Array, wanted: int, steps: int = 24
                  ) -> jax.Array:
    """``keep`` narrowed to each row's ``wanted`` smallest ``dist`` among its kept: a
    bisection on the cut (``steps`` halvings of the row's largest distance), then the
    rows' first points (by pixel order) inside the last interval fill what is left."""
    d = jnp.where(keep, dist, jnp.inf)
    hi = jnp.max(jnp.where(keep, dist, 0.0), 1)  # count(d <= hi) = kept
    lo = -hi  # count(d <= lo) = 0; the interval scales with the distances

    def halve(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        enough = (d <= mid[:, None]).sum(1) >= wanted
        return jnp.where(enough, lo, mid), jnp.where(enough, mid, hi)

    lo, hi = jax.lax.fori_loop(0, steps, halve, (lo, hi))
    inside = d <= lo[:, None]
    edge = (d > lo[:, None]) & (d <= hi[:, None])
    room = wanted - inside.sum(1, keepdims=True)
    return inside | (edge & (jnp.cumsum(edge, 1) <= room))


def window(x: np.ndarray, chosen: np.ndarray, grid: PixelGrid, wanted: int,
           ray: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The patches of the points ``x[chosen]`` of ``x [n, 3]`` on the pixel grid: their
    indices ``[m, k]`` into ``x`` (a masked slot holds the point itself) and weights
    ``[m, k]`` (1: a point of the seed's surface; 0: no point, or one beyond the radius
    of the module docstring), ``k = wanted`` nearest in 3-D of a disc of
    :data:`WINDOW_SHARE` times as many pixels (:func:`nearest`, its kept points
    first). ``ray [n, 3]``: the points' noise along their rays."""
    idx, weight = over_windows(_window_chunk, x, chosen, grid, wanted, ray)
    order = np.argsort(weight <= 0, axis=1, kind="stable")[:, :min(wanted, idx.shape[1])]
    idx, weight = np.take_along_axis(idx, order, 1), np.take_along_axis(weight, order, 1)
    return np.where(weight > 0, idx, chosen[:, None]), weight.astype(np.float64)


def over_windows(fn, x: np.ndarray, chosen: np.ndarray, grid: PixelGrid, wanted: int,
                 ray: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """The results of ``fn(im, at, reach, off, wanted=wanted)`` (jitted, each ``[c,
    ...]``) for the points ``x[chosen]`` on their windows: the frame's :func:`images`
    made once and the points taken :func:`chunked`, each result's chunks joined and cut
    to ``[m, ...]``."""
    off, pad = offsets(wanted, grid)
    im = images(x, grid, pad, ray)
    out = list(chunked(fn, im, chosen, grid, off, ray, wanted=wanted))
    return tuple(np.concatenate([np.asarray(o[i]) for o in out])[:len(chosen)]
                 for i in range(len(out[0])))


@functools.partial(jax.jit, static_argnames="wanted")
def _window_chunk(im: Images, at, reach, off, wanted: int):
    pix, _, weight = nearest(im, at, reach, off, wanted)
    return im.index[pix], weight


def chunked(fn, im: Images, chosen: np.ndarray, grid: PixelGrid, off: np.ndarray,
            ray: np.ndarray | None = None, chunk: int | None = None, **static):
    """``fn(im, at, reach, off, **static)`` (jitted) over the points ``chosen`` in
    chunks of ``chunk`` (None: :data:`SMALL_CHUNK` for a frame of at most
    :data:`SMALL_FRAME` pixels, else :data:`CHUNK`; the last padded with its first
    point: one compiled shape), each given the chunk's padded pixels ``at [chunk]`` and the squared
    reach ``[chunk, k]`` of the window's offsets ``off [k, 2]`` (module docstring);
    yields each chunk's results (the padding's rows included)."""
    h, w = grid.shape
    if chunk is None:
        chunk = SMALL_CHUNK if h * w <= SMALL_FRAME else CHUNK
    flat = grid.flat[chosen]
    at = (flat // w + im.pad) * im.width + flat % w + im.pad
    fp = np.asarray(grid.footprint, np.float64)[chosen]
    reach = (FOOTPRINTS * fp[:, None])**2 * (off**2).sum(1)  # [m, k]
    if ray is not None:  # the seed's noise stands for its neighbour's (about as deep)
        reach = reach + 2.0 * NOISE_SIGMAS**2 * (np.asarray(ray, np.float64)[chosen]**2
                                                 ).sum(1)[:, None]
    off = jnp.asarray(off, jnp.int32)
    for start in range(0, len(chosen), chunk):
        part = np.arange(start, min(start + chunk, len(chosen)))
        part = np.concatenate([part, np.full(chunk - len(part), part[0])])
        yield fn(im, jnp.asarray(at[part], jnp.int32), jnp.asarray(reach[part], jnp.float32),
                 off, **static)


def view_normals(x: np.ndarray, chosen: np.ndarray, grid: PixelGrid) -> np.ndarray:
    """``[m, 3]`` unit: the viewing rays of the points ``x[chosen]`` (from the camera
    centre), the normal a seed takes whose window tells no plane."""
    d = np.asarray(x, np.float64)[chosen] - np.asarray(grid.eye, np.float64)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
