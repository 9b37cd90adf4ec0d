"""The scene learner: a continual map of Gaussian splats from posed RGB-D frames, and the
library's one stream loop.

In the shape of blackjax's algorithms: a :class:`MapState` carried from frame to frame,
a :class:`MapInfo` of per-frame diagnostics, pure functions that take the
hyperparameters as an argument, and :func:`mapper`, which binds them once::

    learner = mapper(Config(components=20000))
    state = learner.init(key=jax.random.key(0))
    for frame in frames:                      # each frame seen once, in arrival order
        state, info = learner.update(state, frame)
    splats = learner.splats(state)            # render with vbgs.render.raster.rasterize

A stream of bare points (an image's pixel patches, ``[n, 2]``; points from elsewhere,
``[n, 3]``) goes through :func:`update_points`, the step every frame goes through too::

    state = init(config, key=key, prior=prior)   # prior: a fixed reference, or None: grow
    for xyz, rgb in batches:
        state, info = update_points(state, xyz, rgb, config)

What one :func:`update` does with a frame (a :class:`vbgs.data.scene.Frame`: camera,
RGB, z-depth):

0. a depth measured by an active sensor (``Config.sensor.white``: noise drawn afresh at
   every pixel) is averaged over each reading's surface first, and the frame's noise is
   scaled by the share the fit leaves (their median; :mod:`vbgs.mapping.denoise`); every
   later step, the opacity evidence's hit band included, reads that depth and that noise;
1. its valid depth pixels become coloured world points (:func:`vbgs.render.camera.unproject`;
   at most ``budget.points`` of them, :mod:`vbgs.mapping.budget`; under
   ``budget.saturation`` those of growth cells already learned that often are skipped,
   :mod:`vbgs.mapping.saturation`), which
   :func:`update_points` learns (2 and 3):
2. a map started empty (``init`` without a ``prior``) grows components where the batch
   shows ground the map has none for (:func:`vbgs.inference.grow.grow`; a frame's seeds
   fit their patches to the points about their pixels, :mod:`vbgs.inference.pixel_patches`,
   bare points to their nearest in a KD-tree); the first
   batch fixes the cell side with ``growth.first_frame_share`` of the capacity; a fixed
   reference under ``config.reseed`` instead moves its unused components onto the
   batch's worst-explained points (:mod:`vbgs.inference.reassign`);
3. one compiled conjugate update learns the points, with their noise along the rays
   when the depth is measured (:mod:`vbgs.mapping.measurement`;
   :class:`vbgs.inference.stepper.Stepper`;
   growth hands it the new rows without recompiling); points farther than
   ``growth.reach_cells`` cells from every component are left out and counted
   (``MapState.n_unlearned``). Under ``config.slow_path`` (re-seeding, or local
   coordinate ascent under posterior assignment, ``local_iters > 1``) the stepper's
   reference :func:`vbgs.inference.model.update` learns them instead;
4. the opacity evidence of the frame's depth map is added (``render.opacity_rule ==
   "evidence"``; :mod:`vbgs.render.opacity`), read against the model that assigned the
   points (the reference after growth, or the posterior before the frame); with
   a measured depth (``Config.sensor``) the hit band widens by the sensor's noise and a
   missing pixel is a pass only where it shows nothing
   (:func:`vbgs.render.background.empty_pixels`: away from the surfaces, or along them
   where it has the ``background``'s colour), never in a hole of a surface; a hole on
   the far side of a depth edge became points at the depth of the surface it continues
   before step 1 (:mod:`vbgs.mapping.holes`);
5. under ``render.colour_rule == "fit"`` the frame's colour least-squares terms are
   added against the splats of the posterior that has just learned it
   (:mod:`vbgs.render.colour_fit`).

With ``components="auto"`` (``"auto:MAX"``) the count is the data's: step 2 grows new
ground at the resolution of the first frame's points (``growth.auto_points`` of them per
cell), splits where a child in a finer cell earns its place (:mod:`vbgs.mapping.splits`:
its Bayes factor from the colours the cell has shown, no finer than the pixel footprint
allows),
optionally merges every few frames the neighbours whose merge raises the bound
(:func:`vbgs.inference.merge.bound_pairs`; off by default) and grows the slots in buckets
(:mod:`vbgs.inference.capacity`) up to MAX (``MapState.capped`` once reached); see
``_auto_room``.

The state is a NamedTuple and is never changed in place; it holds, beside arrays, the
host-side objects a stream needs (the growth rule, and the stepper: the compiled update
with the reference's terms, replaced when the reference grows).

Order invariance holds for what it holds: under prior assignment with a fixed reference
(``init(prior=...)``, ``reseed`` off) the posterior is a sum of per-batch statistics, the
same whatever the order or split of the frames or batches (one batch of all of them
included; ``tests/vbgs/mapping``); a map that grows, or one re-seeded, changes its
reference as batches arrive, and posterior assignment scores each batch under the
current posterior, so those are not (see :mod:`vbgs.inference.grow`).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import NamedTuple

import jax
import numpy as np

from vbgs import sensors
from vbgs.data.scene import Frame
from vbgs.inference import capacity, cells, expfam, grow, kept_pairs, merge, model
from vbgs.inference.pixel_patches import PixelGrid
from vbgs.inference.bound import BatchBound, batch_bound
from vbgs.inference.reassign import reassign
from vbgs.inference.stepper import Stepper
from vbgs.components import AUTO_BUCKET
import vbgs.mapping.saturation as saturation
import vbgs.mapping.change as change
import vbgs.mapping.splits as splits
from vbgs.mapping.budget import on_lattice, stride, thin
from vbgs.mapping.config import Config, frame_search
from vbgs.mapping.denoise import noise_left, smoothed
from vbgs.mapping.holes import fill_holes
from vbgs.mapping.measurement import depth_sigmas, depth_variance, frame_points
from vbgs.mapping.stages import stage
from vbgs.render import colour_fit, opacity
from vbgs.render.background import empty_pixels
from vbgs.render.splats import Splats, drawn, from_posterior, mixture_geometry


class MapState(NamedTuple):
    """What a map carries from frame to frame."""

    mixture: model.State | None  # prior, posterior, statistics; None before a growing
    #                              map's first frame
    key: jax.Array  # split once per frame (growth's random choices)
    rule: grow.Growth | None  # the growth rule, fixed on the first frame (None: no growth)
    stepper: Stepper | None  # the compiled update bound to mixture.prior
    evidence: opacity.Evidence  # rays that hit / passed each component
    colour: colour_fit.ColourNormal  # colour normal equations (colour_rule "fit")
    n_points: int  # points seen (valid depth pixels of every frame)
    n_unlearned: int  # of which left out, beyond reach of every component
    growing: bool  # started empty: components are grown as frames arrive
    n_frames: int = 0  # frames learned
    capped: bool = False  # components="auto" reached its most components (merged to go on)
    seen: saturation.Seen | None = None  # points learned per cell (budget.saturation)
    colours: splits.CellColours | None = None  # colours shown per refinement cell (auto)
    n_skipped: int = 0  # valid points skipped as already explained (budget.saturation)
    doubt: change.Doubt | None = None  # frames in a row each component was seen through
    n_forgotten: int = 0  # components forgotten as gone (vbgs.mapping.change)
    n_merge_rounds: int = 0  # rounds of merges that made room for new ground
    n_merged: int = 0  # components merged into a neighbour in them
    paid: np.ndarray | None = None  # [g, 3] where merged components stood, about the
    #                                 grid's origin: ground the budget paid for (_make_room)
    pending: _Pending | None = None  # the last frame's evidence, not yet observed nor
    #                                  judged (update's defer; settled observes it)

    @property
    def unjudged(self) -> bool:
        """The last frame's evidence waits for :func:`settled` (update's ``defer``)."""
        return self.pending is not None

    @property
    def points_unlearned(self) -> float:
        """The share of the points seen that no component learned."""
        return self.n_unlearned / max(self.n_points, 1)

    @property
    def points_per_component(self) -> float:
        """The median number of points (summed responsibilities) the components that
        learned any hold: a few points each and the splats are about a pixel across,
        too small to close the gaps between them (0.0 before anything is learned)."""
        if self.mixture is None:
            return 0.0
        counts = np.asarray(self.mixture.stats.count, np.float64)
        used = counts[counts > 0]
        return float(np.median(used)) if used.size else 0.0


class MapInfo(NamedTuple):
    """One frame's (or point batch's) diagnostics."""

    elbo: jax.Array  # the batch's ELBO term (scalar, on the device)
    n_points: int  # the batch's points
    n_learned: int  # of which within reach
    n_new: int  # slots changed for the batch (components grown, and merged pairs)
    before: model.Mixture  # the posterior the batch was learned from: after growth or
    #                        re-seeding, before the batch (for the streaming bound)
    after: model.Mixture  # the posterior that learned it, before the frame's evidence
    #                       forgot any component (vbgs.mapping.change)
    xyz: np.ndarray  # [n_learned, d] the points learned
    rgb: np.ndarray  # [n_learned, 3]


class Mapper(NamedTuple):
    """:func:`init`, :func:`update`, :func:`splats`, :func:`update_points` and
    :func:`settled` bound to one :class:`Config`."""

    init: Callable[..., MapState]
    update: Callable[..., tuple[MapState, MapInfo]]
    splats: Callable[..., Splats]
    update_points: Callable[..., tuple[MapState, MapInfo]]
    settled: Callable[[MapState], MapState]


def init(config: Config, *, key: jax.Array, prior: model.Mixture | None = None) -> MapState:
    """A map before any frame or batch. Without ``prior`` it starts empty and grows
    (stream init: nothing read ahead); with one (e.g. :func:`vbgs.inference.model.init`
    on known points: an oracle start when they come from frames not yet arrived) its
    components are fixed and only learned (re-seeded under ``config.reseed``). ``key``:
    growth's and re-seeding's random choices, and a point budget's offsets."""
    k = _first_capacity(config)
    mixture = None
    if prior is None and config.reseed:
        raise ValueError("reseed moves the unused components of a fixed reference; a map "
                         "started empty grows its own: give a prior or leave reseed off")
    if prior is not None and config.auto:
        raise ValueError("components='auto' chooses the components as frames arrive; a "
                         "given prior fixes them: give the prior's count as components")
    if prior is not None:
        if prior.n_components != k or prior.dim not in (2, 3):
            raise ValueError(f"the prior has {prior.n_components} {prior.dim}-D components; "
                             f"the config asks for {k} (3-D for frames, 2-D or 3-D for "
                             f"points)")
        mixture = _measured(model.start(prior), config)
    return MapState(mixture, key, None, None, opacity.no_evidence(k),
                    colour_fit.no_frames(k), 0, 0, prior is None)


def update(state: MapState, frame: Frame, config: Config, background=None, *,
           defer: bool = False) -> tuple[MapState, MapInfo]:
    """Learn one arriving frame (the steps of the module docstring): its depth becomes
    points that go through :func:`update_points`, then the frame's opacity evidence and
    colour terms are added. ``background`` ([3] or None: black) is what the frame's pixels
    without a splat show; the colour fit reads it, and with a measured depth the opacity
    evidence (a depth-less pixel of its colour beside a silhouette shows it; pixels
    without depth are not points).

    ``defer``: the frame's opacity evidence (step 4) is left to the next :func:`update`,
    which sends it to the device once it has split its random keys and judges what it
    forgets after growing its own frame's components: the device works out this frame's
    evidence while the host grows the next one, where otherwise each waits for the
    other (a host read of a new device value waits for all the work queued before it).
    The state returned is then ``unjudged``; :func:`settled` observes and judges it, and
    every function here that reads a map settles it first, so a stream learns the same
    with ``defer`` as without, to the bit (the next frame's growth is made again on the
    settled map after a frame that forgets). Ignored under ``render.colour_rule ==
    "fit"``, whose colour terms read the map after forgetting."""
    with stage("prepare"):
        state, p = _prepare(state, frame, config, background)
    state, info = _update_points(state, p.xyz, p.rgb, config, ray=p.ray,
                                 footprint=p.footprint, weight=p.weight,
                                 camera=frame.camera, pixel=p.pixel)
    state = state._replace(pending=_Pending(info, p, background))
    if not defer or config.render.colour_rule == "fit":
        state = settled(state, config)
    if config.render.colour_rule == "fit":
        with stage("evidence") as done:
            state = _fit_colours(state, frame, config, background)
            done(state.colour)
    return state, info


def _prepare(state: MapState, frame: Frame, config: Config, background):
    """Steps 0 and 1 of the module docstring: the frame's depth averaged and its holes
    filled for a measured sensor, thinned to the budget, unprojected, and its points
    already explained skipped. Returns the state (its key split where the frame was
    thinned or points skipped) and the :class:`_Prepared` frame."""
    sensor = config.sensor
    measured, empty, level = frame, None, sensor.level
    if not sensor.exact:  # holes in surfaces are neither background nor free space
        empty = empty_pixels(frame.depth, holes=True, rgb=frame.rgb, background=background)
        g, cam = config.growth, frame.camera
        focal = 0.5 * (float(cam.fx) + float(cam.fy))
        radius = config.denoise_radius
        if sensor.white and radius:  # the noise averaged over each surface
            depth, factor = smoothed(frame.depth, depth_sigmas(
                frame.depth, cam, sensor.model, sensor.level), focal, radius)
            frame, level = frame._replace(depth=depth), level * noise_left(depth, factor)
        measured = frame._replace(depth=fill_holes(
            frame.depth, frame.rgb, empty, focal, g.hole_radius, g.hole_colour_tol))
    state, depth, weight = _within_budget(state, measured, config)
    xyz, rgb, ray, footprint, pixel = frame_points(  # pixels in raster order
        frame.camera, frame.rgb, depth, sensor.model if sensor.noisy else None, level,
        footprints=state.growing)
    if len(xyz) == 0:
        raise ValueError("the frame has no pixel with valid depth: nothing to learn")
    state, kept, keys = _unexplained(state, xyz, footprint, config)
    if kept is not None:
        xyz, rgb, ray, footprint, weight, keys, pixel = (
            None if a is None else a[kept]
            for a in (xyz, rgb, ray, footprint, weight, keys, pixel))
    return state, _Prepared(xyz, rgb, ray, footprint, weight, keys, pixel, frame, empty,
                            level)


class _Prepared(NamedTuple):
    """A frame as :func:`_prepare` leaves it for the later steps."""

    xyz: np.ndarray  # [n, 3] the points to learn
    rgb: np.ndarray  # [n, 3]
    ray: np.ndarray | None  # [n, 3] their noise along the rays (a measured sensor)
    footprint: np.ndarray | None  # [n] their pixel footprints (a growing map)
    weight: np.ndarray | None  # [n] a thinned frame's weights
    keys: np.ndarray | None  # [n] their cells (budget.saturation)
    pixel: np.ndarray | None  # [n] int their pixels, row * width + col (growth's patches
    # and the projective search's tiles)
    frame: Frame  # its depth averaged (a white-noise sensor)
    empty: np.ndarray | None  # [h, w] pixels that show nothing (a measured sensor)
    level: float  # the sensor's noise level after the averaging


def _observe(state: MapState, info: MapInfo, prepared: _Prepared, config: Config,
             background) -> MapState:
    """Step 4 of the module docstring: the learned points counted in their cells
    (saturation), the frame's opacity evidence added and its see-throughs counted
    (:func:`_judged` decides what they forget)."""
    frame, empty, level = prepared.frame, prepared.empty, prepared.level
    sensor = config.sensor
    state = _count_seen(state, prepared.xyz, prepared.footprint, config, prepared.keys)
    if config.render.opacity_rule == "evidence":  # against the model that assigned
        geometry = mixture_geometry(state.mixture.prior if config.assign == "prior"
                                    else info.before)
        variance = depth_variance(geometry[0], frame.camera, sensor.model, level) \
            if sensor.noisy else None
        e = config.evidence
        reads_colour = state.growing and e.forget_after > 0 and config.recolour_sigmas > 0
        seen = opacity.frame_evidence(  # a sensor's hole is no free space (_through)
            *geometry, frame.camera, frame.depth, pass_sigmas=e.pass_sigmas,
            sensor_var=variance, empty=empty,
            **_through(empty, sensor, e.through_background),
            rgb=frame.rgb if reads_colour else None,
            colour_on=e.recolour_reference == "posterior",
            blame=_blame(state, info, frame, background, config)
            if reads_colour and e.recolour_reference == "map" else None,
            shaped=change.shaped(state.mixture.stats, e.shaped_points)
            if state.growing and sensor.exact else None)  # a sensor's tails: the band
        state = _doubted(state._replace(evidence=opacity.added(state.evidence, seen)),
                         seen, state.evidence, info.before.colour, config)
    return state


class _Pending(NamedTuple):
    """A frame's evidence left to the next frame (:func:`update`'s ``defer``): what
    :func:`_observe` reads."""

    info: MapInfo
    prepared: _Prepared
    background: object  # [3] or None


def settled(state: MapState, config: Config) -> MapState:
    """The map with its last frame's evidence observed and judged (:func:`update`'s
    ``defer``): the components seen through (or recoloured) ``evidence.forget_after``
    frames in a row forgotten (:func:`vbgs.mapping.change.gone`), their slots emptied for
    new ground; a settled map as it is."""
    if not state.unjudged:
        return state
    return _judged(_observed(state, config), config)


def _observed(state: MapState, config: Config) -> MapState:
    """The ``unjudged`` state with its pending evidence added and its see-throughs
    counted, sent to the device and not waited for, still to be :func:`_judged`."""
    info, prepared, background = state.pending
    with stage("evidence") as done:
        state = _observe(state._replace(pending=None), info, prepared, config, background)
        done(state.evidence, state.colour)
    return state


def _fit_colours(state: MapState, frame: Frame, config: Config, background) -> MapState:
    """Step 5 of the module docstring: the frame's colour least-squares terms added
    against the splats of the settled map (``render.colour_rule == "fit"``)."""
    colour = colour_fit.observe(state.colour, _splats(state, config), frame.camera,
                                frame.rgb, 0.0 if background is None else background,
                                blur=config.render.splat_blur)
    return state._replace(colour=colour)


def _through(empty, sensor, background: bool) -> dict:
    """What a frame's pixels without depth prove for the see-through
    (:func:`vbgs.render.opacity.frame_evidence`'s ``through_empty`` and ``through_reach``):
    with exact depth every one is free space; under a measured sensor none, or with
    ``background`` (``evidence.through_background``) and a sensor with a range, the
    pixels that show nothing (``empty``, the background) for components within its range
    (a surface there would have returned a depth); its holes never, nor any pixel of a
    sensor without a known range (a depth network)."""
    if empty is None:
        return {}
    far = getattr(sensors.sensor(sensor.model), "far", None)
    if not background or far is None:
        return {"through_empty": np.zeros_like(empty)}
    return {"through_empty": empty, "through_reach": float(far)}


def _blame(state: MapState, info: MapInfo, frame: Frame, background, config: Config):
    """The ``"map"`` colour reference's ``blame`` (:func:`vbgs.mapping.change.blame`):
    the map before the frame (``info.before``), drawn as :func:`splats` draws it."""
    before = state._replace(mixture=state.mixture._replace(posterior=info.before))
    return change.blame(_splats(before, config), frame.camera, frame.rgb, background,
                        config.recolour_sigmas, config.prior.colour_noise,
                        config.render.splat_blur)


def _doubted(state: MapState, seen: opacity.FrameEvidence, before: opacity.Evidence,
             colour, config: Config) -> MapState:
    """A growing map's run of frames that have seen through (or recoloured: ``colour`` the
    colour posterior before the frame) each component, counted on the device
    (:func:`vbgs.mapping.change.observe`; ``seen`` the frame's evidence, ``before`` the
    evidence before it), which :func:`_judged` reads."""
    if not state.growing or config.evidence.forget_after <= 0:
        return state
    prior = state.mixture.prior
    doubt = change.observe(change.no_doubt(prior.n_components) if state.doubt is None
                           else state.doubt, seen, before, prior.alpha > grow.ACTIVE_ALPHA,
                           reference=config.evidence.recolour_reference, colour=colour,
                           recolour_sigmas=config.recolour_sigmas,
                           colour_noise=config.prior.colour_noise,
                           doubt_opacity=config.doubt_opacity,
                           prior=(config.evidence.prior_hits, config.evidence.prior_passes),
                           apart=config.evidence.recolour_gate > 0)
    return state._replace(doubt=doubt)


def _judged(state: MapState, config: Config) -> MapState:
    """An observed state's components seen through (or recoloured) in
    ``evidence.forget_after`` frames in a row forgotten (:func:`settled`); none where no
    evidence was read (``render.opacity_rule`` other than ``"evidence"``)."""
    if not state.growing or config.evidence.forget_after <= 0 or state.doubt is None:
        return state
    gate = config.evidence.recolour_gate
    slots = change.gone(state.doubt, config.evidence.forget_after, gate, state.n_forgotten)
    if len(slots) == 0:
        return state
    prior = state.mixture.prior
    empty = grow.empty_prior(prior.n_components, prior.origin, state.rule.cell, config.prior,
                             prior.alpha.dtype)
    state = state._replace(paid=_unpaid(state, slots),
                           mixture=change.emptied(state.mixture, slots, empty),
                           evidence=change.cleared(state.evidence, slots),
                           colour=change.cleared(state.colour, slots),
                           doubt=change.cleared(state.doubt, slots),
                           n_forgotten=state.n_forgotten + len(slots))
    return _sync_stepper(state, slots, config)


def update_points(state: MapState, xyz, rgb, config: Config, *, ray=None, footprint=None,
                  weight=None, camera=None, pixel=None) -> tuple[MapState, MapInfo]:
    """Learn one arriving batch of points ``xyz [n, d]``, ``rgb [n, 3]`` (d = 3 for a
    scene, 2 for an image's pixels): the one stream loop's step, which :func:`update`
    takes every frame through after unprojection (steps 2 and 3 of the module
    docstring). A growing map first grows components for the batch's new ground
    (:func:`grow_components`); a fixed reference under ``config.reseed`` first re-seeds
    its unused components onto the batch's worst-explained points. The batch is then
    learned once, by the compiled stepper or, under ``config.slow_path``, by
    :func:`vbgs.inference.model.update` (``config.local_iters`` E-steps of local
    coordinate ascent under posterior assignment). Nothing of the batch is kept.

    ``ray [n, 3]``: measured points' noise along their rays; ``footprint [n]``: their
    pixel footprints (far ground grows coarse cells); ``weight [n]``: each point's weight
    in the statistics (a thinned frame's; None: 1); ``camera``: the frame's camera, which
    the projective candidate search reads (``config.search``); ``pixel [n]`` int: their
    pixels in the camera's image (row * width + col, one point a pixel), where growth
    finds a seed's neighbours (:mod:`vbgs.inference.pixel_patches`; with ``camera`` and
    ``footprint``; None: a KD-tree over the batch) and by which the projective search
    learns the frame's tiles (:mod:`vbgs.inference.frame_tiles`); all from a frame
    (:mod:`vbgs.mapping.measurement`, :mod:`vbgs.mapping.budget`), None for bare points."""
    return _update_points(settled(state, config), xyz, rgb, config, ray=ray,
                          footprint=footprint, weight=weight, camera=camera, pixel=pixel)


def _update_points(state: MapState, xyz, rgb, config: Config, *, ray=None, footprint=None,
                   weight=None, camera=None, pixel=None) -> tuple[MapState, MapInfo]:
    """:func:`update_points` on a map that may be ``unjudged``
    (:func:`grow_components` decides it)."""
    if len(xyz) == 0:
        raise ValueError("the batch has no points: nothing to learn")
    with stage("grow") as done:
        state, slots = grow_components(state, xyz, rgb, config, ray, footprint,
                                       pixel_grid(pixel, camera, footprint, config))
        done(state.mixture)
    with stage("search+step") as done:
        state, before, elbo, learned = _learn(state, slots, xyz, rgb, config, ray, footprint,
                                              weight, camera, pixel)
        done(state.mixture)
    n = len(xyz)
    if learned is not None:  # points beyond reach were left out
        xyz, rgb = xyz[learned], rgb[learned]
    state = state._replace(n_points=state.n_points + n,
                           n_unlearned=state.n_unlearned + n - len(xyz),
                           n_frames=state.n_frames + 1)
    return state, MapInfo(elbo, n, len(xyz), len(slots), before, state.mixture.posterior, xyz,
                          rgb)


def _learn(state: MapState, slots, xyz, rgb, config: Config, ray, footprint, weight, camera,
           pixel=None) -> tuple[MapState, model.Mixture, jax.Array, np.ndarray | None]:
    """:func:`update_points`' step 3: the batch learned once, by the compiled stepper
    (its terms brought up to the grown ``slots`` first) or under ``config.slow_path``
    by :func:`_learn_slowly`. Returns the state, the posterior the batch was learned
    from, the batch's ELBO term and which points were within reach (None: all)."""
    if config.slow_path:
        state, before, elbo = _learn_slowly(state, xyz, rgb, config)
        return state, before, elbo, None
    state = _sync_stepper(state, slots, config, frame_search(config.search, camera))
    reach = None  # each point's own, when far ground has coarse cells
    levels = grow.point_levels(state.rule, footprint) if state.growing else None
    if levels is not None and state.stepper.reach is not None:
        reach = state.stepper.reach * 2.0**levels
    before = state.mixture.posterior
    if camera is not None and pixel is not None:  # a thinned frame searched on its lattice
        camera, pixel = on_lattice(camera, pixel, _stride(camera, config))
    mixture, step = state.stepper(state.mixture, xyz, rgb, ray, reach, weight, camera, pixel)
    return state._replace(mixture=mixture), before, step.elbo, step.learned


def _learn_slowly(state: MapState, xyz, rgb, config: Config
                  ) -> tuple[MapState, model.Mixture, jax.Array]:
    """:func:`update_points`' learning under ``config.slow_path``: the batch through
    :func:`vbgs.inference.model.update`, after re-seeding the reference under
    ``config.reseed`` (its unused components moved onto the points worst explained under
    the assigning model; the state's key split once). Returns the state, the posterior the
    batch was learned from and the batch's ELBO term."""
    learn = partial(model.update, assign=config.assign, config=config.prior,
                    estep=config.estep, n_candidates=config.n_candidates,
                    local_iters=config.local_iters)
    mixture = state.mixture
    if config.reseed:
        key, sub = jax.random.split(state.key)
        _, scored = learn(mixture, xyz, rgb)
        mixture, _ = reassign(mixture, xyz, rgb, scored.point_loglik, key=sub,
                              colour_noise=config.prior.colour_noise)
        state = state._replace(key=key)
    before = mixture.posterior
    mixture, info = learn(mixture, xyz, rgb)
    return state._replace(mixture=mixture), before, info.elbo


def splats(state: MapState, config: Config, drop_unused: bool = False) -> Splats:
    """The map's splats: posterior means and scaled expected covariances, opacities by
    ``render.opacity_rule``, colours by ``render.colour_rule``. ``drop_unused`` keeps
    only the splats drawn (:func:`vbgs.render.splats.drawn`; components that saw no data
    have opacity 0); else every slot stays, a fixed splat count. An ``unjudged`` map is
    :func:`settled` first."""
    state = settled(state, config)
    colours = None
    if config.render.colour_rule == "fit":
        colours = colour_fit.solve(state.colour, state.mixture.posterior.colour.mean,
                                   ridge=config.render.colour_ridge)
    out = _splats(state, config, drop_unused, colours)
    return drawn(out) if drop_unused else out


def bound(info: MapInfo, config: Config) -> BatchBound:
    """The streaming bound ``B_t`` (:mod:`vbgs.inference.bound`) of the frame that
    ``info`` describes: from the posterior it was learned from to the one that learned
    it. Components the frame's evidence then forgot (:mod:`vbgs.mapping.change`) are
    not counted here: forgetting is no update by the frame's points but a new prior for
    the frames after it (a change point), which the next frame's ``before`` holds. Read
    against the map after forgetting, a forgotten component's KL, from its posterior
    back to its prior, is that of all the data it ever held (the walk: -1.7e10 nats for
    a frame that forgot 2 components, the stream's bound negative)."""
    return batch_bound(info.before, info.after, info.xyz, info.rgb,
                       config=config.prior, estep=config.estep,
                       n_candidates=config.n_candidates)


def mapper(config: Config) -> Mapper:
    """The functions with ``config`` bound: ``init(key=..., prior=None)``,
    ``update(state, frame, background=None, defer=False)``, ``splats(state,
    drop_unused=False)``, ``update_points(state, xyz, rgb, ray=None, footprint=None,
    weight=None)`` and ``settled(state)``."""

    def bound_init(*, key: jax.Array, prior: model.Mixture | None = None) -> MapState:
        return init(config, key=key, prior=prior)

    def bound_update(state: MapState, frame: Frame, background=None, defer: bool = False):
        return update(state, frame, config, background, defer=defer)

    def bound_splats(state: MapState, drop_unused: bool = False) -> Splats:
        return splats(state, config, drop_unused)

    def bound_update_points(state: MapState, xyz, rgb, **measured):
        return update_points(state, xyz, rgb, config, **measured)

    return Mapper(bound_init, bound_update, bound_splats, bound_update_points,
                  partial(settled, config=config))


def pixel_grid(pixel, camera, footprint, config: Config) -> PixelGrid | None:
    """A frame's points on its pixel grid (:mod:`vbgs.inference.pixel_patches`): their
    pixels ``pixel [n]`` in the image of ``camera``, on the lattice of the frame's
    budget (:func:`vbgs.mapping.budget.stride`), with their ``footprint [n]``; None
    when any is missing (bare points)."""
    if pixel is None or camera is None or footprint is None:
        return None
    return PixelGrid(np.asarray(pixel), (int(camera.height), int(camera.width)),
                     _stride(camera, config),
                     np.asarray(footprint), np.asarray(camera.pose, np.float64)[:3, 3])


def grow_components(state: MapState, xyz, rgb, config: Config, ray=None, footprint=None,
                    pixel: PixelGrid | None = None) -> tuple[MapState, np.ndarray]:
    """Step 2 of :func:`update_points` alone: a growing map's new components for the points
    ``xyz [n, 3]``, ``rgb [n, 3]`` (new ground; none for a map with a fixed reference),
    and the slots they filled. The first call fixes the growth rule; ``ray [n, 3]``:
    the points' noise along their rays, ``footprint [n]`` their pixel footprints
    (:mod:`vbgs.mapping.measurement`; far ground gets coarse cells); ``pixel``: the
    points on the frame's pixel grid, where the seeds' patches are found
    (:func:`pixel_grid`; None: a KD-tree over the batch).

    An ``unjudged`` map (:func:`update`'s ``defer``) splits its keys, sends its last
    frame's evidence to the device and grows as though that frame forgot nothing, while
    the device works the evidence out; when it did forget, that growth is dropped and
    made again on the :func:`settled` map, the merges' kept pairs put back as the first
    growth found them (:mod:`vbgs.inference.kept_pairs`), so the answer is the settled
    map's either way."""
    if not state.unjudged:
        return _grow(state, xyz, rgb, config, ray, footprint, pixel)
    keys = jax.block_until_ready(tuple(jax.random.split(state.key)))  # before the evidence
    observed, kept = _observed(state, config), kept_pairs.kept()
    grown, slots = _grow(observed, xyz, rgb, config, ray, footprint, pixel, keys)
    judged = _judged(observed, config)
    if judged.n_forgotten == observed.n_forgotten:  # nothing forgotten: the growth stands
        return grown, slots
    kept_pairs.put_back(kept)  # the history the merges would have seen (ties alike)
    return _grow(judged, xyz, rgb, config, ray, footprint, pixel, keys)


def _grow(state: MapState, xyz, rgb, config: Config, ray=None, footprint=None,
          pixel: PixelGrid | None = None, keys=None) -> tuple[MapState, np.ndarray]:
    """:func:`grow_components` on a settled map (the same arguments); ``keys``: the
    state's key split already, ``(key, sub)`` as ``jax.random.split`` gives them."""
    if not state.growing:
        return state, np.zeros(0, np.int64)
    mixture, rule = state.mixture, state.rule
    k, g = config.max_components, config.growth
    if mixture is None:  # the first frame fixes the cell side
        first, refine = g.first_frame_share * k, g.refine_share
        if config.auto:  # the sensor's resolution, not a share of K; see _auto_room
            first, refine = len(xyz) / g.auto_points, 1.0 if g.split else 0.0
        rule = grow.calibrate(xyz, k, first, refine=refine,
                              levels=g.levels, rate=g.max_new_share, footprint=footprint,
                              coarse=g.coarse_levels, coarse_from=g.coarse_from)
        mixture = _measured(grow.start_empty(xyz, _first_capacity(config), rule.cell,
                                             config.prior), config)
    key, sub = jax.random.split(state.key) if keys is None else keys
    levels = _spent_levels(state, grow.point_levels(rule, footprint), len(xyz), config)
    state = state._replace(mixture=mixture, rule=rule)
    earns = found = None  # found: the frame's new ground, where the merges' count found it
    if config.auto:
        state, merged = _auto_room(state, xyz, ray, levels, config)
        state, earns = _split_levels(state, xyz, rgb, footprint, config)
        state = _auto_widen(state, xyz, ray, levels, earns, config)
    else:
        state, merged, found = _make_room(state, xyz, ray, levels, config)
    mixture, info = grow.grow(state.mixture, xyz, rgb, _refining(state, rule, config),
                              key=sub, config=config.prior,
                              ray=ray, levels=levels, earns=earns, pixel=pixel,
                              held=_held(state, config), found=found)
    return state._replace(mixture=mixture, key=key), np.concatenate([merged, info.slots])


def _refining(state: MapState, rule: grow.Growth, config: Config) -> grow.Growth:
    """The growth rule a frame grows by: once the map has forgotten components as gone
    (:mod:`vbgs.mapping.change`; ``growth.changed_refine``) and fewer slots are empty than
    a fresh map refines in a frame (``refine_share`` of K), ``rule`` with refinement free
    to take every empty slot new ground leaves; else ``rule``.

    Why: the refine share is a share of the empty slots so that a stream keeps slots for
    ground it meets later. Once the budget is spent, that ground is paid for by merges
    anyway, and what the share keeps back is a few hundred slots: ground met late (or
    revealed, or grown again where the world changed) is then learned no finer than its
    first cells, while what was learned first keeps the detail it was refined to with
    slots to spare. That is the right trade where the world stays as it was (it holds
    what was learned first); in a world seen to change, the ground a frame shows now is
    the world as it is, and the slots left go to its detail as a fresh map's would, with
    merges of what the data tell apart least paying for the ground to come
    (:func:`_make_room` counts new ground only, so those come in the next frame that
    meets new ground). While more slots are empty (a change that emptied many, the
    changing object's thousands) the share holds them for the ground the change will
    show next. A static stream never forgets and never grows by it. On the changing
    scenes' validation views, seeds 0-2, it gains 0.22-0.38 dB in the room and 0.25-0.44
    on the walk, and moves the object by -0.04 to +0.02 (``results/tuning/
    changed_refine/``)."""
    if config.auto or not config.growth.changed_refine or state.n_forgotten == 0:
        return rule
    if grow.empty_slots(state.mixture) > rule.refine * config.max_components:
        return rule
    return rule._replace(refine=1.0)


def _spent_levels(state: MapState, levels: np.ndarray | None, n: int, config: Config
                  ) -> np.ndarray | None:
    """The growth levels of a frame's ``n`` points (``levels [n]``, their coarse levels,
    or None: all 0) once the budget is spent: ``growth.spent_levels`` coarser after the
    map's first round of merges (the points as they are before it, or with the setting
    0); ``"ground"``: as many as the ground the stream has met allows
    (:func:`ground_levels`). Why: a stream that keeps meeting new ground with every slot
    in use pays for each new component by merging two it learned before, and at the
    cells it started with it pays as much for the ground it meets last as for the ground
    it met first: a 200-frame walk over new ground at 20k components merged 104k
    components in 161 rounds and its first views fell 2 dB from when they were seen."""
    up = config.growth.spent_levels
    if up == "ground":
        up = ground_levels(state.n_merged, config.max_components)
    if up <= 0 or state.n_merge_rounds == 0:
        return levels
    return np.full(n, up, np.int64) if levels is None else levels + up


def ground_levels(merged: int, k: int) -> int:
    """The cell levels new ground may take coarser once ``merged`` components have been
    merged to make room in ``k`` slots: each merge paid for a component of new ground, so
    the stream has met about ``1 + merged / k`` times the ground its ``k`` slots first
    held, and the same ``k`` slots spread over it hold surfaces at that many times the
    area each, a side ``sqrt`` of it: ``floor(log4(1 + merged / k))`` levels (a level
    doubles the side). A stream that meets its ground once and stays in it (one lap of a
    room, which merges about ``k`` in all) never reaches a level; a 200-frame walk over
    new ground reaches one after merging ``3 k``."""
    return int(np.floor(np.log(1.0 + merged / k) / np.log(4.0)))


def _within_budget(state: MapState, frame: Frame, config: Config
                   ) -> tuple[MapState, np.ndarray, np.ndarray | None]:
    """The frame's depth thinned to ``budget.points`` points (:mod:`vbgs.mapping.budget`;
    the offset drawn under the state's key, split only when the frame is thinned) and
    the kept points' weights; the frame's own depth and None within the budget."""
    b = config.budget
    if _stride(frame.camera, config) == 1:
        return state, frame.depth, None
    key, sub = jax.random.split(state.key)
    depth, weight = thin(frame.depth, b.points, key=sub, weighted=b.weighted)
    return state._replace(key=key), depth, weight


def _stride(camera, config: Config) -> int:
    """The lattice a frame of ``camera``'s size is thinned to under ``budget.points``
    (:func:`vbgs.mapping.budget.stride`; 1: learned whole)."""
    return stride(int(camera.width), int(camera.height), config.budget.points)


def _unexplained(state: MapState, xyz, footprint, config: Config
                 ) -> tuple[MapState, np.ndarray | None, np.ndarray | None]:
    """The frame's points to learn under ``budget.saturation``
    (:mod:`vbgs.mapping.saturation`: a point of a cell already learned that often is
    skipped), as a mask ``[n]``, the cells of the points ``[n]`` and the state with its
    key split and the skipped points counted; None, None (every point) without the limit
    or before the growth rule is fixed."""
    cap = config.budget.saturation
    if cap <= 0 or state.rule is None or state.seen is None:
        return state, None, None
    key, sub = jax.random.split(state.key)
    keys = _cell_keys(state, xyz, footprint)
    kept = saturation.keep(state.seen, keys, cap, key=sub)
    if not kept.any():  # nothing new: one point keeps the step's shapes and counters
        kept[0] = True
    return state._replace(key=key, n_skipped=state.n_skipped + int((~kept).sum())), kept, keys


def _count_seen(state: MapState, xyz, footprint, config: Config, keys=None) -> MapState:
    """The state with the frame's learned points ``xyz [n, 3]`` counted in their cells
    (``budget.saturation`` only; the table starts with the growth rule). ``keys [n]``:
    their cells when :func:`_unexplained` found them (the rule and origin are fixed by
    then); None: found here (the first frame, which fixes them)."""
    if config.budget.saturation <= 0 or state.rule is None:
        return state
    seen = state.seen if state.seen is not None else saturation.nothing_seen()
    keys = _cell_keys(state, xyz, footprint) if keys is None else keys
    return state._replace(seen=saturation.add(seen, keys))


def _cell_keys(state: MapState, xyz, footprint) -> np.ndarray:
    """``[n]`` the growth cells of the points ``xyz`` (their own coarse level)."""
    return saturation.cell_keys(state.rule, xyz, state.mixture.prior.origin,
                                grow.point_levels(state.rule, footprint))


def _make_room(state: MapState, xyz, ray, levels, config: Config
               ) -> tuple[MapState, np.ndarray, grow.Ground | None]:
    """Free slots by merging (:mod:`vbgs.inference.merge`) when the frame shows more new
    ground than the empty slots can take (``growth.merge``); the state with the pairs
    merged (statistics, opacity evidence and colour sums alike), the slots changed, and
    the frame's new ground where it was found and nothing merged (:func:`vbgs.inference.
    grow.ground_of`: growth then picks from it rather than look it up again; None else).
    A round frees what the frame lacks, at least ``growth.merge_ahead`` of K (its comment
    says how it is chosen). The pairs are the merge's own choice, redone only where
    components changed since the last round (:mod:`vbgs.inference.kept_pairs`)."""
    mixture, rule, g = state.mixture, state.rule, config.growth
    none = np.zeros(0, np.int64)
    if not g.merge:
        return state, none, None
    with stage("merge") as done:
        held, found = _held(state, config), None
        if grow.short_of_slots(mixture, rule):
            found = grow.ground_of(mixture, xyz, rule, ray=ray, levels=levels, held=held)
        short = grow.shortfall(mixture, xyz, rule, ray=ray, levels=levels, held=held,
                               found=found)
        if short <= 0:
            return state, none, found
        prior = mixture.prior
        counts = np.asarray(mixture.stats.count, np.float64)
        n_pairs = max(short, int(g.merge_ahead * prior.n_components))
        pairs = kept_pairs.choose_pairs(mixture.posterior, counts, grow.is_active(prior),
                                        n_pairs, config.prior.colour_noise)
        if g.hold_paid:
            state = state._replace(paid=_paid(state, pairs))
        state = _merged(state, pairs, config)
        done(state.mixture)
    return state._replace(n_merge_rounds=state.n_merge_rounds + 1,
                          n_merged=state.n_merged + len(pairs)), pairs.reshape(-1), None


def _held(state: MapState, config: Config) -> np.ndarray | None:
    """``[g, 3]`` positions (about the grid's origin) whose cells growth counts as held
    besides those of the components' posterior means (:func:`vbgs.inference.grow.grow`'s
    ``held``): the prior means of the components in use (``growth.hold_seeds``: under
    prior assignment a component's prior row is the reference that assigns the ground
    about its seed, wherever its posterior mean has moved since) and the ground merges
    paid for (``growth.hold_paid``, :func:`_paid`); None when neither."""
    g, prior = config.growth, state.mixture.prior
    parts = []
    if g.hold_seeds:
        parts.append(np.asarray(prior.space.mean, np.float64)[grow.is_active(prior)])
    if g.hold_paid and state.paid is not None:
        parts.append(state.paid)
    return np.concatenate(parts) if parts else None


def _paid(state: MapState, pairs: np.ndarray) -> np.ndarray:
    """``state.paid`` with the means of both ends of ``pairs [p, 2]`` (before the merge)
    added, about the grid's origin, one per cell of the finest level (``growth.hold_paid``).

    Why: a merge moves the pair's mass to its moment match between them, and the cell one
    of them stood in is then new ground to growth (no mean lies in it): the next frame
    that sees it grows a component there, which the budget pays for by merging another
    pair (on the room at fit-scene's defaults about half the new ground grown after the
    first ten frames lay in cells a component had held before: a count made once with a
    patched learner, not kept). The merged component still draws that ground (its
    covariance spans the pair), so the cells stay held. Measured in
    ``results/tuning/hold/`` and ``results/changing/static/walk_long200_hold.json``."""
    mixture, rule = state.mixture, state.rule
    means = np.asarray(mixture.posterior.space.mean, np.float64)[pairs.reshape(-1)]
    paid = means if state.paid is None else np.concatenate([state.paid, means])
    fine = rule.cell / 2.0 ** max(rule.levels - 1, 0)
    _, first = np.unique(cells.cell_keys(cells.cell_index(paid, fine)), return_index=True)
    return paid[np.sort(first)]


def _unpaid(state: MapState, slots: np.ndarray) -> np.ndarray | None:
    """``state.paid`` less the positions in the level-0 cells of the components ``slots``
    (forgotten as gone, :mod:`vbgs.mapping.change`): what stands there now is new ground."""
    if state.paid is None or len(state.paid) == 0 or len(slots) == 0:
        return state.paid
    mixture, cell = state.mixture, state.rule.cell
    gone = np.asarray(mixture.posterior.space.mean, np.float64)[slots]
    (paid_keys, gone_keys), size = cells.box_keys([state.paid, gone], cell)
    return state.paid[~cells.held(gone_keys, paid_keys, size)]


def _merged(state: MapState, pairs: np.ndarray, config: Config) -> MapState:
    """The state with ``pairs [p, 2]`` merged (:func:`vbgs.inference.merge.merge`):
    statistics, opacity evidence and colour sums alike."""
    if len(pairs) == 0:
        return state
    mixture, prior = state.mixture, state.mixture.prior
    empty = grow.empty_prior(prior.n_components, prior.origin, state.rule.cell, config.prior,
                             prior.alpha.dtype)
    return state._replace(mixture=merge.merge(mixture, pairs, empty),
                          evidence=merge.merge_rows(state.evidence, pairs),
                          colour=merge.merge_rows(state.colour, pairs),
                          doubt=None if state.doubt is None else change.cleared(
                              state.doubt, pairs.reshape(-1)))


def _auto_room(state: MapState, xyz, ray, levels, config: Config
               ) -> tuple[MapState, np.ndarray]:
    """``components="auto"``: the count follows the data by births and merges.

    Births are :func:`vbgs.inference.grow.grow`'s new ground at a resolution the data
    set: the first frame fixes the cell side so that each level-0 cell holds about
    ``growth.auto_points`` of its points (the sensor's own sampling, whatever the
    scene's extent); finer cells come only from the splits below. Every ``growth.auto_merge_every`` frames (0, the default:
    never; figures in :mod:`vbgs.components`) the neighbours whose merge raises the bound
    are merged (:func:`vbgs.inference.merge.bound_pairs`, the derivation in
    :mod:`vbgs.inference.merge`). Splits come after this room is made
    (``_split_levels``, ``_auto_widen``): a point seeds a child in a finer cell where
    the child's log Bayes factor, from every colour the cell has shown, exceeds
    ``growth.refine_gain`` (:mod:`vbgs.mapping.splits`). When the
    frame's new ground wants more slots than are empty the capacity grows to the next bucket (:mod:`vbgs.inference.capacity`: a compilation
    per bucket, not per frame); at ``config.max_components`` it stops growing, the state
    says so (``capped``) and the cheapest pairs are merged as under a fixed K."""
    g = config.growth
    merged = np.zeros(0, np.int64)
    every = g.auto_merge_every
    if g.merge and every and state.n_frames and state.n_frames % every == 0:
        mixture = state.mixture
        pairs = merge.bound_pairs(mixture, grow.is_active(mixture.prior),
                                  config.prior.colour_noise)
        state, merged = _merged(state, pairs, config), pairs.reshape(-1)
    short = grow.shortfall(state.mixture, xyz, state.rule, ray=ray, levels=levels,
                           held=_held(state, config))
    k0 = state.mixture.prior.n_components
    if short > 0:
        state = _widened(state, k0 + short, config)
        k = state.mixture.prior.n_components
        if k0 + short > k:  # at the ceiling: make room as a fixed K does
            state, more, _ = _make_room(state._replace(capped=True), xyz, ray, levels,
                                        config)
            merged = np.concatenate([merged, more])
    return state, merged


def _widened(state: MapState, wanted: int, config: Config) -> MapState:
    """The state with capacity for ``wanted`` slots (the bucket that holds them, at most
    ``config.max_components``; :mod:`vbgs.inference.capacity`)."""
    k0 = state.mixture.prior.n_components
    k = capacity.bucket(wanted, AUTO_BUCKET, config.max_components)
    if k <= k0:
        return state
    return state._replace(
        mixture=capacity.widen(state.mixture, k, state.rule.cell, config.prior),
        evidence=capacity.widen_rows(state.evidence, k),
        colour=capacity.widen_rows(state.colour, k),
        doubt=None if state.doubt is None else capacity.widen_rows(state.doubt, k))


def _split_levels(state: MapState, xyz, rgb, footprint, config: Config
                  ) -> tuple[MapState, np.ndarray | None]:
    """``components="auto"``: the refinement levels ``[n, levels]`` each point of the
    batch may seed (:mod:`vbgs.mapping.splits`: where a child's log Bayes factor, from
    every colour its cell has shown, exceeds ``growth.refine_gain``, in cells no finer than
    ``growth.refine_footprints`` pixel footprints), and the state with the batch's colours
    counted; None when splits are off (``growth.split``)."""
    g = config.growth
    if not g.split:
        return state, None
    mixture = state.mixture
    table = state.colours if state.colours is not None else \
        splits.no_colours(shape=g.refine_shape)
    earns, table = splits.earned_levels(
        state.rule, mixture.posterior, grow.is_active(mixture.prior), xyz, rgb, table,
        prior=config.prior, gain=g.refine_gain, footprint=footprint, floor=g.refine_footprints)
    return state._replace(colours=table), earns


def _auto_widen(state: MapState, xyz, ray, levels, earns, config: Config) -> MapState:
    """Capacity for the refinement ``earns`` asks for as well as the new ground (births
    beyond the ceiling are not made: refinement never merges to make room)."""
    if earns is None or not earns.any():
        return state
    short = grow.shortfall(state.mixture, xyz, state.rule, ray=ray, levels=levels,
                           earns=earns, held=_held(state, config))
    if short <= 0:
        return state
    return _widened(state, state.mixture.prior.n_components + short, config)


def _first_capacity(config: Config) -> int:
    """The slots a map starts with: K, or under ``auto`` the first bucket."""
    if config.auto:
        return capacity.bucket(1, AUTO_BUCKET, config.max_components)
    return config.max_components


def _measured(mixture: model.State, config: Config) -> model.State:
    """A fresh mixture state whose statistics carry the noise moments when the depth is
    measured (the same structure from the first frame on: no second compilation)."""
    if not config.sensor.noisy:
        return mixture
    prior = mixture.prior
    return mixture._replace(stats=expfam.zero_stats(prior.n_components, prior.dim,
                                                    prior.alpha.dtype, noisy=True))


def _sync_stepper(state: MapState, slots: np.ndarray, config: Config,
                  search: str = "kdtree") -> MapState:
    """The stepper for the state's reference: built on the first frame (with the
    candidate ``search`` its frames take, :func:`vbgs.mapping.config.frame_search`),
    grown (a new stepper sharing the compiled step) after the frame's growth filled
    ``slots``."""
    prior = state.mixture.prior
    if state.stepper is None or state.stepper.prior.n_components != prior.n_components:
        reach, stepper_search, spacing = None, "auto", None
        if state.growing and config.estep == "sparse":
            reach = grow.reach_of(state.rule, config.growth.reach_cells)
        if search == "projective" and config.estep == "sparse" and prior.dim == 3:
            stepper_search = "projective"
            spacing = state.rule.cell if state.growing else grow.mean_spacing(prior)
        step = Stepper(prior, assign=config.assign, config=config.prior, estep=config.estep,
                       n_candidates=config.n_candidates, grows=state.growing, reach=reach,
                       follow=config.budget.saturation > 0, search=stepper_search,
                       spacing=spacing)
    elif len(slots):
        step = state.stepper.grow(prior, slots)
    else:
        return state
    return state._replace(stepper=step)


def _splats(state: MapState, config: Config, drop_unused: bool = False,
            colours=None) -> Splats:
    """The posterior's splats with ``colours [k, 3]`` in place of the colour means when
    given."""
    if state.mixture is None:
        raise ValueError("the map has seen no frame yet: there are no splats to show")
    r = config.render
    opacities = None
    if r.opacity_rule == "evidence":
        e = config.evidence
        opacities = opacity.expected_opacity(state.evidence, e.prior_hits, e.prior_passes)
    return from_posterior(state.mixture.posterior, state.mixture.prior, opacity=r.opacity,
                          cov_scale=r.splat_scale, drop_unused=drop_unused,
                          opacities=opacities, colours=colours)
