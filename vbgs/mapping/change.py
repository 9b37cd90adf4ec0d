"""A world that changes: components whose surface has gone are found from the frames'
own depth and forgotten, so that growth re-learns the place as it now is.

**The evidence.** Each frame's opacity evidence (:func:`vbgs.render.opacity.frame_evidence`)
already reads, per component, its depth map along a few rays through the component's
footprint, with the hit band widened by the sensor's noise. A component is **seen
through** in a frame when the ray through its mean and four rays at least
``THROUGH_PIXELS`` pixels either side of it (in u and in v) all end beyond its far side
(or show nothing): free space where the map holds a surface. A removed object's
components are seen through from every view that looks at the place; a surface that
is still there is hit. A frame that hits a component, with any of its rays, shows it
there; a frame in which it is occluded or out of view says nothing.

**Its far side, along each ray.** Where a component ends along a ray is a question
about the Gaussian restricted to that ray. With ``c`` the camera centre, ``r`` the
ray's direction scaled to unit camera depth and ``P = Σ⁻¹``, the density along
``c + t r`` is a Gaussian in ``t`` (camera depth) with mean
``t* = rᵀ P (μ - c) / rᵀ P r`` and variance ``1 / rᵀ P r``; the sensor's variance of a
reading there adds to it (the hit band's ``sensor_var``), so noise is not change. A
ray has passed the component when its reading lies beyond ``t*`` by more than
``pass_sigmas`` of that standard deviation. For a surface component (flat along its
normal) ``t*`` is where the ray crosses its plane, wherever in the footprint the ray
falls, and the band is its thickness seen along the ray. The opacity band (the
component's whole extent along the camera axis, ``PASS_SIGMAS`` marginal sigmas) takes
a surface that lies behind a removed component, but within that extent, as a hit, and
keeps the component; along the ray it lies beyond. The components that touched the
ground a removed object stood on are still hit there (the ground is within their own
thickness): their ghost of its footprint goes only with colour evidence. The opacity
evidence keeps its band; only the see-through
test reads the component along the ray. ``evidence.shaped_points``
(``SHAPED_POINTS``) leaves components holding fewer points to the band (inf: every one, the test as it was): on the changing scenes'
validation views fewer is better, 0 (every component along the ray) the best of 0 to
inf (``results/tuning/shaped/``), and at 0 the static streams forget what they forgot
with the band, no more (object and room nothing, the walk the same two components a
pixel wide at 20 m). Under a measured sensor the band stays: along the ray the band
narrows to the sensor's sigma, and its tails (a Kinect's flying pixels at edges,
quantised disparity) then read as free space several frames in a row (the static object
under the Kinect forgot tens of components where it forgot two with the band); a
measured depth is judged against the component's extent along the camera axis, as
before.

**The test, per component and in closed form.** Two hypotheses, *still there* and
*gone*. Under *gone* every frame that looks is a see-through; under *still there* a
see-through is the rare misreading of a pixel grid (a thin pole that one frame's pixels
miss, a silhouette's own component beside its edge), with some small probability
``epsilon`` per frame, and a hit resets the question. After ``n`` consecutive
see-throughs with no hit the log odds of *gone* against *still there* have grown by
``n log(1/epsilon)``; the prior odds of a change are small, so the decision is a count:
``n >= forget_after`` frames in a row (``EvidenceConfig.forget_after``; 0: never). A
component that was never hit (``MIN_HITS`` rays) is not a surface the map learned and
is left to the opacity evidence.

**Who may be doubted.** ``epsilon`` is small for a surface its rays hit, not for a
component thinner than a pixel: a lamp post or a tree crown at 20 m, at 128 px, is hit
only in the frames whose pixel centres happen to fall on it, and its rays pass it about
as often as they hit it, so runs of see-throughs come by chance (the static walk's
stream forgets two such components). The component's own evidence tells it apart: the
expected opacity of the rays that met it (:func:`vbgs.render.opacity.expected_opacity`,
its hits against its passes over the stream), near 1 for a surface and about 0.4 for
those two. With ``EvidenceConfig.doubt_opacity`` above 0 a run of doubt starts only on a
component whose expected opacity is at least that; a run once started goes on (the
see-throughs of a change lower the opacity as they count). At 0.5 the static object,
room and walk with exact depth are what they are with forgetting off, to the bit (the
walk's two components are kept), and the changing scenes lose a few hundredths of a dB
(``results/changing/*.doubt50.json``, ``results/changing/static/*.doubt50.json``). Under
the Kinect the static object and room forget floaters in front of the background at
either setting (209 and 100 components at 0.5, 212 and 101 at 0: the see-through
against the background below). Under the Kinect's noise fewer of a removed object's components are opaque enough to be
doubted: the changing object forgets 6417 components where it forgets 6568, 22.78 dB
against 22.84 (at 0.4 22.82), and at 0.4 the walk forgets its two again
(``*.doubt40.json``). So with exact depth the default is 0.5
(:data:`EXACT_DOUBT_OPACITY`) and under a measured sensor 0, any component.

**Colour.** A surface repainted in place is hit as before, so depth alone never tells
it; nor does it tell a moved object's components that touched the ground it stood on
(their rays hit the ground within the band, and they draw the object's colour there: a
ghost of its footprint). With ``EvidenceConfig.recolour_sigmas`` above 0 a frame also
reads the colour at a component's sample rays that hit it (at least
``MIN_COLOUR_HITS`` of the five) and counts against the component when their mean lies
too far from the colour the component is known by (``recolour_reference``):

* ``"history"`` (the default): farther than ``recolour_sigmas`` colour sigmas (the
  model's ``colour_noise``) from the mean of what its earlier frames' rays showed (at
  least ``MIN_COLOUR_FRAMES`` of them, each agreeing). A frame that agrees joins the
  history and, as a hit, resets the count; one that disagrees does not join it. Two
  frames' pixels are a thin reference: where later views' rays land elsewhere on a
  texture, or on the neighbouring face of an edge, every later frame disagrees, and
  static streams forget hundreds of components (``results/changing/static/``).
* ``"posterior"``: judged against the component's own colour posterior
  ``N(m, σ_c² / κ I)`` (before the frame; while a run of doubt lasts, the posterior
  before it, so that the frames after a change do not drag the reference after them).
  Where nothing changed, a hit ray's colour is ``c = m + e``: ``m`` off by the
  posterior's ``σ_c² / κ`` a channel, ``e`` the colour noise ``σ_c²`` a channel plus
  the spread of colour the component covers where the rays land (a texture). That
  spread is estimated from the frame itself, the rays' own squared scatter about their
  mean ``S`` (the statistics hold no second moment of colour), so the expected squared
  distance of their mean from ``m`` is at most ``E = 3 σ_c² (1 + 1/κ) + S`` (``S`` not
  divided by the number of rays: rays a few pixels apart on a texture are not
  independent). A frame counts against the component when the squared distance exceeds
  ``recolour_sigmas² E``; by Markov's inequality a still surface does that with
  probability at most ``1 / recolour_sigmas²`` a frame, whatever the colours'
  distribution, and ``forget_after`` frames in a row are needed. Two guards come from
  where the static streams' false recolourings were found. (i) Edge components seen from
  one side: their side rays land on the neighbouring face within the hit band (a crate's
  top seen past its side's component, a platform's rim), a surface the component never
  explained. Only rays whose surface point lies within ``pass_sigmas`` Mahalanobis
  sigmas of the component's own Gaussian are read
  (:func:`vbgs.render.opacity.frame_evidence`, ``colour_on``). (ii) Components of a few
  points: their colour mean is a few pixels, whose spread is unknown (the predictive of
  a colour under an unknown variance is a Student t with the points less one degrees of
  freedom, heavy-tailed for a few); judged from ``MIN_COLOUR_POINTS`` points on.

At ``recolour_sigmas`` 6 the posterior reference is safe: the static object, room and
walk streams, and the object and room under the Kinect, are what they are with colour
off, to the bit (``results/changing/static/*.posterior6.json``; at 4 the object and the
walk each forget one component more). It is not the default because it then tells
little on object-change and room-change against depth alone
(``results/changing/*.posterior6.json``), and on the validation views hardly more than
no colour, where the history at 4 gains over a dB (``results/tuning/recolour/``).
Most of a changed world's colour evidence lies where the static false alarms did, on
rays that land off the component's Gaussian (a new surface standing within an old one's
band), and most of its components hold fewer than ``MIN_COLOUR_POINTS`` points at
128 px: telling a face the map already holds from a new one needs the map's other
components along that ray, which this per-component test does not read.

* ``"map"``: the history's test, and the map as a whole must fail to explain the
  colour where it is read. The map before the frame is drawn at the frame's pose
  (:func:`vbgs.render.raster.rasterize`, as it is shown): where nothing changed a
  pixel's colour is that render's plus the colour noise, ``σ_c²`` a channel, so its
  squared distance from the render has mean ``3 σ_c²``, and by Markov's inequality it
  lies beyond ``recolour_sigmas² 3 σ_c²`` with probability at most
  ``1 / recolour_sigmas²``. A pixel is *unexplained* when it and its eight neighbours
  all lie beyond (:func:`unexplained`): the render's blur and a pixel's misregistration
  along an edge put a line a pixel wide off the render, a change puts a patch. A
  sample ray of a component is *blamed* when it hits the component, its pixel is
  unexplained and the pixel's colour lies beyond the same tolerance from the
  component's own colour mean too (the component draws the wrong colour there: a
  neighbour of the right colour is not blamed for a ghost beside it;
  :func:`vbgs.render.opacity.frame_evidence`, ``blame``). A frame counts against the
  component when its history disagrees and ``MIN_COLOUR_HITS`` of its rays are blamed.
  An edge component whose side rays land on the neighbouring face is not blamed: the
  neighbour's components draw that face's colour there. The render's blend of colours
  at a pixel (its second moment) was tried as a further allowance and dropped: on a
  texture it covers every change (object-change at 4 gained nothing over depth
  alone). At ``recolour_sigmas`` 2 the static object stream is what it is with colour
  off, to the bit, and object-change gains a few tenths of a dB over depth alone; far
  less than the history's gain: most of that gain lies on pixels the map already
  explains, a new surface's colour learned by the components about it within a frame
  or two of the change (``results/changing/``).

**A colour gate.** Every colour test above false-alarms somewhere on a static stream,
and for one reason: a component at a rim between two differently coloured faces is a
surface of both, and a view from the other side lands its rays, within its own Gaussian,
on the face its earlier frames did not show (the static object's recoloured components
lie in lines along the platform's and the crate's rims; reading every ray rather than
their mean, or only rays on the component's own Gaussian, leaves tens to hundreds of
them). A single component cannot tell that from a repainting; the stream can. Whether
the world changes at all is one question for the whole map, with a prior that a static
world answers no, and depth answers it without false alarms: with exact depth a static
stream's see-throughs forget no component, or a handful (the thin posts of the walk),
where a world that changed loses its removed objects' components by the hundred or
thousand. So under ``EvidenceConfig.recolour_gate`` colour keeps a run of frames of its
own per component (``Doubt.runs``, apart from the see-throughs' ``frames``), and a
component recoloured ``forget_after`` frames in a row is forgotten only once the map
has forgotten at least that share of its slots (counting the frame's own see-throughs):
the world has shown that it changes, and a colour that stays changed is then taken as
the change it most likely is. A static world never opens the gate, so its stream is
what it is with colour off, to the bit (colour is read, but nothing it counts reaches
the map). The runs are counted from the first frame, so the components repainted with
the change are forgotten as soon as the gate opens, not ``forget_after`` frames later.
What it gives up: a world that changes only in colour (a repainting and nothing moved)
never opens it, and is drawn as depth alone draws it. By default with exact depth (the
history's test at 4 colour sigmas behind a gate of 0.5% of the slots, the best gated
setting on the changing scenes' validation views, ``results/tuning/recolour_gate/``;
:data:`vbgs.mapping.config.RECOLOUR_GATE`): object-change 26.32 dB on its test views
against 24.73 by depth alone, 26.44 without the gate and 26.80 for a fresh map of the
changed world; room-change 22.51 against 21.78, 22.70 and 22.95
(``results/changing/``). Under a measured sensor colour stays off: depth's tails forget
floaters there by the hundred, and no share of the slots tells a static world.

Only a measured return beyond the component is free space for this test: with exact
depth a pixel without depth shows nothing (sky, empty space) and counts as well, but a
sensor's missing pixel (out of its range, a hole) says nothing about what stands there.
Nothing, that is, beyond its range: a pixel that shows the background (no depth, joined
to the image's border, :func:`vbgs.render.background.empty_pixels`) says that no surface
stands along its ray within the range, where a surface would have returned a depth. With
``EvidenceConfig.through_background`` such pixels count as seen through for the
components whose hit band ends within the sensor's range (its holes inside surfaces
never count): an object that left the view against the background is then forgotten
under a sensor as it is with exact depth. Without the range the room's far walls, out of
the Kinect's 4.5 m and so without depth, were forgotten from every frame that looked
past them (a one-off run: the static room under the Kinect 21.48 dB against 21.85 with
it off, at older code); with it the static room scores 21.86 against 21.86. On by
default, by the
validation views of the changing and the static object and room under the Kinect, which
it wins on each (``results/tuning/through_background/``); ``results/changing/``'s
``*.kinect.nobackground.json`` are the same streams with it off.

The count is the one choice, and a constraint rather than a tuned figure: the fewest
frames at which the static streams forget (almost) nothing. See-throughs of a static
world come in runs on the synthetic walk (its thin lamp posts and tree crowns at 20 m,
a pixel wide at 128 px; object and room at most one frame, exact depth, 60 frames
each). At six the object and room streams with exact
depth, and the room under the Kinect, are what they are with forgetting off, to the bit;
the object under the Kinect forgets one component and the walk three (seven frames:
two; ``results/changing/static/``). With colour behind the gate (the default with exact
depth) six is also the best of 3, 6 and 8 on the changing scenes' validation views
(``results/tuning/forget/``), so the count is no higher.

**Forgetting.** A gone component's slot is emptied, the way a merge empties the slot it
frees: prior row back to an empty slot's, its statistics, opacity evidence and colour
sums zeroed. Its learned statistics are not discounted (a forgetting factor or a power
prior would keep drawing a fading ghost of the object, and would touch components the
frame never contradicted); the place is new ground again, and the next frame that shows
what now stands there grows components for it. Only components a frame saw through are
touched: everything the world kept is left to the bit.

**Re-learning.** What grows there is refined as it is shown, as a fresh map's first
frames are: once the map has forgotten anything and its budget is spent (fewer slots empty than
``refine_share`` of the capacity), growth's refinement may take every empty slot new
ground leaves rather than that share of them, merges paying for the ground to come
(``growth.changed_refine``, ``vbgs.mapping.mapper._refining``). Without it the ground
revealed behind a removed object, or grown again on a repainted one, stays at its first
cells while what was learned with slots to spare keeps its detail: the continual room's
table top where its ball stood, and the repainted stool, were blurred beside a fresh
map's (with it the table top is sharper, though its changed pixels still score about
a dB under a fresh map's, ``results/changing/room-change{,.fresh}.json``). A static
stream never forgets, so it never refines so.

It reads a growing map (``init`` without a prior): a fixed reference has no empty slot
to return a component to, so under a given prior nothing is forgotten, and a stream of
a fixed reference still equals one batch.
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference import model
from vbgs.inference.model import Mixture
from vbgs.render.opacity import (PRIOR_HITS, PRIOR_PASSES, Evidence, FrameEvidence,
                                 expected_opacity)
from vbgs.render.raster import rasterize

# Frames in a row seen through, no frame hitting it, after which a component is gone
# (module docstring: static streams of object, room and walk forget nothing).
FORGET_AFTER = 6
# Rays that must have hit a component before it can be judged gone (a surface learned).
MIN_HITS = 5.0
# With exact depth a run of doubt starts only on a component at least this opaque (module
# docstring, "Who may be doubted"); under a measured sensor any component may be doubted.
EXACT_DOUBT_OPACITY = 0.5
# A frame reads a component's colour when this many of its five sample rays hit it (a
# majority: one pixel beside an edge does not decide). Against the history of its rays
# (``recolour_reference="history"``), the mean of at least this many earlier frames that
# read it and agreed; against its colour posterior ("posterior"), one that holds at least
# this many points (module docstring: a colour mean of a few pixels says little about the
# spread of the colours the component covers).
MIN_COLOUR_HITS = 3
MIN_COLOUR_FRAMES = 2
MIN_COLOUR_POINTS = 10.0
RECOLOUR_REFERENCES = ("history", "posterior", "map")

# A component holding at least this many points is judged seen through along each ray's
# Gaussian, one with fewer against the hit band (module docstring: 0, every component,
# is the best on validation views, results/tuning/shaped/, and forgets nothing static).
SHAPED_POINTS = 0.0

_m_step = jax.jit(model.m_step)


def shaped(stats, points: float = SHAPED_POINTS) -> jax.Array:
    """``[k]`` bool: the components whose statistics hold ``points`` points or more."""
    return stats.count >= points


class Doubt(NamedTuple):
    """Per component, the frames in a row it was seen through (or recoloured) since a
    frame hit it, and the colour it is judged against as ``colour / weight``: under the
    ``"history"`` reference the sum of the mean colours its rays showed in the frames
    that agreed and their number; under ``"posterior"`` its colour posterior's mean times
    its precision in points and that precision, before the first frame of a run of doubt
    while one lasts (module docstring)."""

    frames: jax.Array  # [k] int32
    colour: jax.Array  # [k, 3]
    weight: jax.Array  # [k]
    runs: jax.Array  # [k] int32: frames in a row recoloured, counted apart from ``frames``
    #                  under a colour gate (EvidenceConfig.recolour_gate; 0 without one)


def no_doubt(k: int) -> Doubt:
    """Before any frame: no component doubted, no colour known."""
    return Doubt(jnp.zeros(k, jnp.int32), jnp.zeros((k, 3), jnp.float32),
                 jnp.zeros(k, jnp.float32), jnp.zeros(k, jnp.int32))


@partial(jax.jit, static_argnames="apart")
def _history(doubt: Doubt, hits, seen_through, judged, shown, n_shown, colour_tol,
             blamed=None, apart: bool = False):
    """The history's test; with ``blamed [k]`` (the ``"map"`` reference) a disagreeing
    frame counts against a component only where ``MIN_COLOUR_HITS`` of its rays are
    blamed (the map as a whole does not explain them either); ``apart``: recolourings
    counted in their own run (:func:`_runs`)."""
    readable = n_shown >= MIN_COLOUR_HITS
    before = doubt.colour / jnp.maximum(doubt.weight, 1.0)[:, None]
    off = (readable & (doubt.weight >= MIN_COLOUR_FRAMES)
           & (((shown - before) ** 2).sum(-1) > colour_tol**2))
    agrees = readable & ~off  # the colour the component is known by
    recoloured = off if blamed is None else off & (blamed >= MIN_COLOUR_HITS)
    frames, runs = _runs(doubt, hits, seen_through, recoloured, judged, apart)
    return Doubt(frames, doubt.colour + jnp.where(agrees[:, None], shown, 0.0),
                 doubt.weight + agrees, runs)


@partial(jax.jit, static_argnames="apart")
def _posterior(doubt: Doubt, hits, seen_through, judged, shown, n_shown, spread, mean, kappa,
               sigmas, colour_noise, apart: bool = False):
    held = (doubt.runs if apart else doubt.frames) > 0  # in a run of doubt (of colour,
    #                                    apart): judged against the colour before it
    kappa = jnp.where(held, doubt.weight, kappa)
    mean = jnp.where(held[:, None], doubt.colour / jnp.maximum(kappa, 1e-6)[:, None], mean)
    expected = 3.0 * colour_noise**2 * (1.0 + 1.0 / jnp.maximum(kappa, 1e-6)) + spread
    recoloured = ((n_shown >= MIN_COLOUR_HITS) & (kappa >= MIN_COLOUR_POINTS)
                  & (((shown - mean) ** 2).sum(-1) > sigmas**2 * expected))
    frames, runs = _runs(doubt, hits, seen_through, recoloured, judged, apart)
    return Doubt(frames, mean * kappa[:, None], kappa, runs)


@jax.jit
def unexplained(rgb, rendered, sigmas, colour_noise):
    """Where the map as a whole fails to explain a frame's colour (module docstring,
    ``"map"``): ``rgb [h, w, 3]`` the frame, ``rendered [h, w, 3]`` the map drawn at its
    pose. Returns ``[h, w]`` bool: the squared colour distance between frame and render
    lies above ``sigmas² 3 σ_c²`` (``colour_noise`` ``σ_c``) at the pixel and at each of
    its eight neighbours (a pixel's misregistration along an edge, a line a pixel wide,
    is not change), and that tolerance ``[h, w]``."""
    h, w = rgb.shape[:2]
    tolerance = jnp.full((h, w), sigmas**2 * 3.0 * colour_noise**2, jnp.float32)
    residual = jnp.pad(((rgb - rendered) ** 2).sum(-1), 1, mode="edge")
    least = jnp.min(jnp.stack([residual[i:i + h, j:j + w] for i in range(3)
                               for j in range(3)]), 0)
    return least > tolerance, tolerance


def blame(splats, camera, rgb, background, sigmas: float, colour_noise: float,
          blur: float):
    """``blame`` of :func:`vbgs.render.opacity.frame_evidence` under the ``"map"``
    reference: the map's ``splats`` rendered at the frame's ``camera`` (``background``
    [3] or None: black), the pixels of ``rgb [h, w, 3]`` it fails to explain
    (:func:`unexplained`), the tolerance there and the splats' own colours."""
    bg = jnp.zeros(3, jnp.float32) if background is None else jnp.asarray(background,
                                                                           jnp.float32)
    rendered = rasterize(splats, camera, background=bg, blur=blur).rgb
    bad, tolerance = unexplained(jnp.asarray(rgb, jnp.float32), rendered,
                                 jnp.float32(sigmas), jnp.float32(colour_noise))
    return bad, tolerance, splats.colours


def _count(frames, hits, against, judged):
    """The frames in a row: one more where the frame counts ``against`` a ``judged``
    component, 0 where it hit it otherwise, kept where it said nothing."""
    return jnp.where(against & judged, frames + 1, jnp.where(hits > 0, 0, frames))


def _runs(doubt: Doubt, hits, seen_through, recoloured, judged, apart: bool):
    """``(frames, runs)`` after a frame: see-throughs and recolourings in one run
    (``runs`` stays 0), or ``apart`` in a run each (a colour gate, module docstring)."""
    if not apart:
        return _count(doubt.frames, hits, seen_through | recoloured, judged), doubt.runs
    return (_count(doubt.frames, hits, seen_through, judged),
            _count(doubt.runs, hits, recoloured, judged))


def colour_tolerance(recolour_sigmas: float, colour_noise: float) -> float:
    """How far a frame's colour on a component may lie from what earlier frames showed
    before it counts against the component under the ``"history"`` reference:
    ``recolour_sigmas`` colour sigmas (``colour_noise``); infinite when 0 (colour tells
    no change, none is read)."""
    return recolour_sigmas * colour_noise if recolour_sigmas > 0 else math.inf


def observe(doubt: Doubt, frame: FrameEvidence, evidence: Evidence, active, *,
            reference: str = "history", colour=None, recolour_sigmas: float = 0.0,
            colour_noise: float = 0.0, doubt_opacity: float = 0.0,
            prior: tuple[float, float] = (PRIOR_HITS, PRIOR_PASSES),
            apart: bool = False) -> Doubt:
    """``doubt`` after one frame's evidence ``frame``: a see-through of an ``active [k]``
    component hit ``MIN_HITS`` rays or more before (``evidence``, the counts before the
    frame), or a recolouring, adds one; any other hit resets the count; a frame without
    either keeps it. A recolouring (module docstring), none when ``recolour_sigmas`` is 0:
    ``MIN_COLOUR_HITS`` or more sample rays read and, under ``reference="history"``,
    their mean colour farther than ``recolour_sigmas`` colour sigmas (``colour_noise``)
    from the mean of those its earlier agreeing frames showed; under ``"posterior"``
    farther from its colour posterior's mean (``colour``, a
    :class:`vbgs.inference.expfam.ColourNormal` before the frame; the one before the run
    of doubt while one lasts, holding ``MIN_COLOUR_POINTS`` points or more) than
    ``recolour_sigmas`` times the distance expected where nothing changed; under
    ``"map"`` the history's test and ``MIN_COLOUR_HITS`` or more rays blamed
    (``frame.blamed``: the map as a whole and the component's own colour both fail to
    explain their pixels, :func:`blame`). With ``doubt_opacity`` above 0 a run starts only
    on a component whose expected opacity under the evidence's Beta ``prior`` (hits,
    passes) is at least that (module docstring, "Who may be doubted"). ``apart``:
    recolourings counted in their own run, ``doubt.runs`` (a colour gate, module
    docstring; :func:`gone`)."""
    judged = jnp.asarray(active) & (evidence.hits >= MIN_HITS)
    if doubt_opacity > 0:
        judged = judged & ((doubt.frames > 0)
                           | (expected_opacity(evidence, *prior) >= doubt_opacity))
    args = (doubt, frame.hits, frame.seen_through, judged, frame.shown, frame.n_shown)
    if reference == "posterior" and recolour_sigmas > 0:
        return _posterior(*args, frame.spread, colour.mean, colour.kappa,
                          jnp.float32(recolour_sigmas), jnp.float32(colour_noise), apart=apart)
    return _history(*args, jnp.float32(colour_tolerance(recolour_sigmas, colour_noise)),
                    frame.blamed if reference == "map" and recolour_sigmas > 0 else None,
                    apart=apart)


def gone(doubt: Doubt, forget_after: int, gate: float = 0.0, n_forgotten: int = 0
         ) -> np.ndarray:
    """``[m]`` the components seen through ``forget_after`` frames in a row (none when
    0), and under a colour ``gate`` those recoloured that many frames in a row in their
    own run (``doubt.runs``) once the gate is open: :func:`gate_open` with the map's
    ``n_forgotten`` before the frame and the frame's own see-throughs."""
    if forget_after <= 0:
        return np.zeros(0, np.int64)
    out = np.asarray(doubt.frames) >= forget_after
    if gate_open(n_forgotten + int(out.sum()), len(out), gate):
        out = out | (np.asarray(doubt.runs) >= forget_after)
    return np.flatnonzero(out)


def gate_open(n_forgotten: int, n_components: int, gate: float) -> bool:
    """Whether recoloured components may be forgotten under a colour gate of ``gate``
    (a share of the slots; module docstring): the map has forgotten at least that share
    of its ``n_components`` slots by its frames' depth (``n_forgotten``, with the frame's
    own see-throughs). Never without a gate (0)."""
    return gate > 0 and n_forgotten >= max(gate * n_components, 1)


def emptied(state: model.State, slots: np.ndarray, empty: Mixture) -> model.State:
    """``state`` with the components ``slots [m]`` emptied: their prior rows taken from
    ``empty`` (a prior of empty slots, :func:`vbgs.inference.grow.empty_prior`), their
    statistics zeroed, the posterior the M-step of the two."""
    if len(slots) == 0:
        return state
    prior = jax.tree_util.tree_map(lambda p, e: _rows(p, e, slots), state.prior._replace(
        origin=None), empty._replace(origin=None))._replace(origin=state.prior.origin)
    stats = cleared(state.stats, slots)
    return state._replace(prior=prior, posterior=_m_step(prior, stats), stats=stats)


def cleared(sums, slots: np.ndarray):
    """Per-component sums (a NamedTuple of ``[k, ...]`` arrays or None) with the rows
    ``slots`` zeroed."""
    def one(x):
        if x is None:
            return None
        out = np.array(x)
        out[slots] = 0
        return jax.device_put(out)

    return type(sums)(*(one(x) for x in sums))


def _rows(field, source, slots: np.ndarray):
    """``field`` with its rows ``slots`` taken from ``source`` (on the host, as growth
    puts rows: a device scatter would compile once per number of slots)."""
    out = np.array(field)
    out[slots] = np.asarray(source)[slots]
    return jax.device_put(out)
