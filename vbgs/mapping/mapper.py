"""The scene learner: a continual map of Gaussian splats from posed RGB-D frames.

In the shape of blackjax's algorithms: a :class:`MapState` carried from frame to frame,
a :class:`MapInfo` of per-frame diagnostics, pure functions that take the
hyperparameters as an argument, and :func:`mapper`, which binds them once::

    learner = mapper(Config(components=20000))
    state = learner.init(key=jax.random.key(0))
    for frame in frames:                      # each frame seen once, in arrival order
        state, info = learner.update(state, frame)
    splats = learner.splats(state)            # render with vbgs.render.raster.rasterize

What one :func:`update` does with a frame (a :class:`vbgs.data.scene.Frame`: camera,
RGB, z-depth):

1. its valid depth pixels become coloured world points (:func:`vbgs.render.camera.unproject`);
2. a map started empty (``init`` without a ``prior``) grows components where the frame
   shows ground the map has none for (:func:`vbgs.inference.grow.grow`); the first
   frame fixes the cell side with ``growth.first_frame_share`` of the capacity;
3. the opacity evidence of the frame's depth map is added (``render.opacity_rule ==
   "evidence"``; :mod:`vbgs.render.opacity`), read against the assigning model; with
   a measured depth (``Config.sensor``) the hit band widens by the sensor's noise and a
   missing pixel is a pass only where it shows nothing
   (:func:`vbgs.render.background.empty_pixels`: away from the surfaces, or along them
   where it has the ``background``'s colour), never in a hole of a surface;
4. one compiled conjugate update learns the points, with their noise along the rays
   when the depth is measured (:mod:`vbgs.mapping.measurement`;
   :class:`vbgs.inference.stepper.Stepper`;
   growth hands it the new rows without recompiling); points farther than
   ``growth.reach_cells`` cells from every component are left out and counted
   (``MapState.n_unlearned``);
5. under ``render.colour_rule == "fit"`` the frame's colour least-squares terms are
   added against the splats of the posterior that has just learned it
   (:mod:`vbgs.render.colour_fit`).

With ``components="auto"`` (``"auto:MAX"``) the count is the data's: step 2 grows at the
resolution of the first frame's points (``growth.auto_points`` of them per cell), merges
every few frames the neighbours whose merge raises the bound
(:func:`vbgs.inference.merge.bound_pairs`) and grows the slots in buckets
(:mod:`vbgs.inference.capacity`) up to MAX (``MapState.capped`` once reached); see
``_auto_room``.

The state is a NamedTuple and is never changed in place; it holds, beside arrays, the
host-side objects a stream needs (the growth rule, and the stepper: the compiled update
with the reference's terms, replaced when the reference grows). Under prior assignment
with a fixed reference (``init(prior=...)``) the posterior is the same whatever the
order of the frames; a map that grows changes its reference as frames arrive, so it is
not (see :mod:`vbgs.inference.grow`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import numpy as np

from vbgs.data.scene import Frame
from vbgs.inference import capacity, expfam, grow, merge, model
from vbgs.inference.bound import BatchBound, batch_bound
from vbgs.inference.stepper import Stepper
from vbgs.components import AUTO_BUCKET
from vbgs.mapping.budget import stride, thin
from vbgs.mapping.config import Config
from vbgs.mapping.measurement import depth_variance, point_footprints, point_rays
from vbgs.render import colour_fit, opacity
from vbgs.render.background import empty_pixels
from vbgs.render.camera import unproject
from vbgs.render.splats import Splats, drawn, from_posterior, mixture_geometry


class MapState(NamedTuple):
    """What a map carries from frame to frame."""

    mixture: model.State | None  # prior, posterior, statistics; None before a growing
    #                              map's first frame
    key: jax.Array  # split once per frame (growth's random choices)
    rule: grow.Growth | None  # the growth rule, fixed on the first frame (None: no growth)
    stepper: Stepper | None  # the compiled update bound to mixture.prior
    geometry: tuple | None  # means [k, 3], covariances [k, 3, 3] of mixture.prior
    evidence: opacity.Evidence  # rays that hit / passed each component
    colour: colour_fit.ColourNormal  # colour normal equations (colour_rule "fit")
    n_points: int  # points seen (valid depth pixels of every frame)
    n_unlearned: int  # of which left out, beyond reach of every component
    growing: bool  # started empty: components are grown as frames arrive
    n_frames: int = 0  # frames learned
    capped: bool = False  # components="auto" reached its most components (merged to go on)

    @property
    def points_unlearned(self) -> float:
        """The share of the points seen that no component learned."""
        return self.n_unlearned / max(self.n_points, 1)


class MapInfo(NamedTuple):
    """One frame's diagnostics."""

    elbo: jax.Array  # the frame's ELBO term (scalar, on the device)
    n_points: int  # the frame's points
    n_learned: int  # of which within reach
    n_new: int  # components grown for the frame
    before: model.Mixture  # the posterior before the frame (for the streaming bound)
    xyz: np.ndarray  # [n_learned, 3] the points learned
    rgb: np.ndarray  # [n_learned, 3]


class Mapper(NamedTuple):
    """:func:`init`, :func:`update` and :func:`splats` bound to one :class:`Config`."""

    init: Callable[..., MapState]
    update: Callable[..., tuple[MapState, MapInfo]]
    splats: Callable[..., Splats]


def init(config: Config, *, key: jax.Array, prior: model.Mixture | None = None) -> MapState:
    """A map before any frame. Without ``prior`` it starts empty and grows (stream
    init: nothing read ahead); with one (e.g. :func:`vbgs.inference.model.init` on
    known points: an oracle start when they come from frames not yet arrived) its
    components are fixed and only learned."""
    k = _first_capacity(config)
    mixture = None
    if prior is not None and config.auto:
        raise ValueError("components='auto' chooses the components as frames arrive; a "
                         "given prior fixes them: give the prior's count as components")
    if prior is not None:
        if prior.n_components != k or prior.dim != 3:
            raise ValueError(f"the prior has {prior.n_components} {prior.dim}-D components; "
                             f"the config asks for {k} 3-D ones")
        mixture = _measured(model.start(prior), config)
    return MapState(mixture, key, None, None, None, opacity.no_evidence(k),
                    colour_fit.no_frames(k), 0, 0, prior is None)


def update(state: MapState, frame: Frame, config: Config,
           background=None) -> tuple[MapState, MapInfo]:
    """Learn one arriving frame (the steps of the module docstring). ``background``
    ([3] or None: black) is what the frame's pixels without a splat show; the colour
    fit reads it, and with a measured depth the opacity evidence (a depth-less pixel of
    its colour beside a silhouette shows it; pixels without depth are not points)."""
    state, depth, weight = _within_budget(state, frame, config)
    xyz, rgb = unproject(frame.camera, frame.rgb, depth)
    if len(xyz) == 0:
        raise ValueError("the frame has no pixel with valid depth: nothing to learn")
    sensor = config.sensor
    ray = point_rays(frame.camera, depth, sensor.model, sensor.level) if sensor.noisy else None
    footprint = point_footprints(frame.camera, depth) if state.growing else None
    state, slots = grow_components(state, xyz, rgb, config, ray, footprint)
    state = _sync_stepper(state, slots, config)
    reach = None  # each point's own, when far ground has coarse cells
    levels = grow.point_levels(state.rule, footprint) if state.growing else None
    if levels is not None and state.stepper.reach is not None:
        reach = state.stepper.reach * 2.0**levels
    evidence = state.evidence
    if config.render.opacity_rule == "evidence":  # against the model that assigns
        geometry = (state.geometry if config.assign == "prior"
                    else mixture_geometry(state.mixture.posterior))
        variance = depth_variance(geometry[0], frame.camera, sensor.model, sensor.level) \
            if sensor.noisy else None
        evidence = opacity.observe(evidence, *geometry, frame.camera, frame.depth,
                                   pass_sigmas=config.evidence.pass_sigmas,
                                   sensor_var=variance,
                                   empty=empty_pixels(frame.depth, holes=not sensor.exact,
                                                      rgb=frame.rgb, background=background))
    before = state.mixture.posterior
    mixture, step = state.stepper(state.mixture, xyz, rgb, ray, reach, weight)
    n = len(xyz)
    if step.learned is not None:  # points beyond reach were left out
        xyz, rgb = xyz[step.learned], rgb[step.learned]
    state = state._replace(mixture=mixture, evidence=evidence, n_points=state.n_points + n,
                           n_unlearned=state.n_unlearned + n - len(xyz),
                           n_frames=state.n_frames + 1)
    if config.render.colour_rule == "fit":
        colour = colour_fit.observe(state.colour, _splats(state, config), frame.camera,
                                    frame.rgb, 0.0 if background is None else background,
                                    blur=config.render.splat_blur)
        state = state._replace(colour=colour)
    return state, MapInfo(step.elbo, n, len(xyz), len(slots), before, xyz, rgb)


def splats(state: MapState, config: Config, drop_unused: bool = False) -> Splats:
    """The map's splats: posterior means and scaled expected covariances, opacities by
    ``render.opacity_rule``, colours by ``render.colour_rule``. ``drop_unused`` keeps
    only the splats drawn (:func:`vbgs.render.splats.drawn`; components that saw no data
    have opacity 0); else every slot stays, a fixed splat count."""
    colours = None
    if config.render.colour_rule == "fit":
        colours = colour_fit.solve(state.colour, state.mixture.posterior.colour.mean,
                                   ridge=config.render.colour_ridge)
    out = _splats(state, config, drop_unused, colours)
    return drawn(out) if drop_unused else out


def bound(info: MapInfo, state: MapState, config: Config) -> BatchBound:
    """The streaming bound ``B_t`` (:mod:`vbgs.inference.bound`) of the frame that
    ``info`` describes, ``state`` being the map right after it."""
    return batch_bound(info.before, state.mixture.posterior, info.xyz, info.rgb,
                       config=config.prior, estep=config.estep,
                       n_candidates=config.candidates)


def mapper(config: Config) -> Mapper:
    """The three functions with ``config`` bound: ``init(key=..., prior=None)``,
    ``update(state, frame, background=None)``, ``splats(state, drop_unused=False)``."""

    def bound_init(*, key: jax.Array, prior: model.Mixture | None = None) -> MapState:
        return init(config, key=key, prior=prior)

    def bound_update(state: MapState, frame: Frame, background=None):
        return update(state, frame, config, background)

    def bound_splats(state: MapState, drop_unused: bool = False) -> Splats:
        return splats(state, config, drop_unused)

    return Mapper(bound_init, bound_update, bound_splats)


def grow_components(state: MapState, xyz, rgb, config: Config, ray=None, footprint=None
                    ) -> tuple[MapState, np.ndarray]:
    """Step 2 of :func:`update` alone: a growing map's new components for the points
    ``xyz [n, 3]``, ``rgb [n, 3]`` (new ground; none for a map with a fixed reference),
    and the slots they filled. The first call fixes the growth rule; ``ray [n, 3]``:
    the points' noise along their rays, ``footprint [n]`` their pixel footprints
    (:mod:`vbgs.mapping.measurement`; far ground gets coarse cells)."""
    if not state.growing:
        return state, np.zeros(0, np.int64)
    mixture, rule = state.mixture, state.rule
    k, g = config.max_components, config.growth
    if mixture is None:  # the first frame fixes the cell side
        first, refine = g.first_frame_share * k, g.refine_share
        if config.auto:  # the sensor's resolution, not a share of K; see _auto_room
            first, refine = len(xyz) / g.auto_points, 0.0
        rule = grow.calibrate(xyz, k, first, refine=refine,
                              levels=g.levels, rate=g.max_new_share, footprint=footprint,
                              coarse=g.coarse_levels, coarse_from=g.coarse_from)
        mixture = _measured(grow.start_empty(xyz, _first_capacity(config), rule.cell,
                                             config.prior), config)
    key, sub = jax.random.split(state.key)
    levels = grow.point_levels(rule, footprint)
    room = _auto_room if config.auto else _make_room
    state, merged = room(state._replace(mixture=mixture, rule=rule), xyz, ray, levels, config)
    mixture, info = grow.grow(state.mixture, xyz, rgb, rule, key=sub, config=config.prior,
                              ray=ray, levels=levels)
    return state._replace(mixture=mixture, key=key), np.concatenate([merged, info.slots])


def _within_budget(state: MapState, frame: Frame, config: Config
                   ) -> tuple[MapState, np.ndarray, np.ndarray | None]:
    """The frame's depth thinned to ``budget.points`` points (:mod:`vbgs.mapping.budget`;
    the offset drawn under the state's key, split only when the frame is thinned) and
    the kept points' weights; the frame's own depth and None within the budget."""
    b = config.budget
    cam = frame.camera
    if stride(int(cam.width), int(cam.height), b.points) == 1:
        return state, frame.depth, None
    key, sub = jax.random.split(state.key)
    depth, weight = thin(frame.depth, b.points, key=sub, weighted=b.weighted)
    return state._replace(key=key), depth, weight


def _make_room(state: MapState, xyz, ray, levels, config: Config
               ) -> tuple[MapState, np.ndarray]:
    """Free slots by merging (:mod:`vbgs.inference.merge`) when the frame shows more new
    ground than the empty slots can take (``growth.merge``); the state with the pairs
    merged (statistics, opacity evidence and colour sums alike) and the slots changed."""
    mixture, rule = state.mixture, state.rule
    none = np.zeros(0, np.int64)
    if not config.growth.merge:
        return state, none
    short = grow.shortfall(mixture, xyz, rule, ray=ray, levels=levels)
    if short <= 0:
        return state, none
    prior = mixture.prior
    counts = np.asarray(mixture.stats.count, np.float64)
    n_pairs = max(short, int(config.growth.merge_ahead * prior.n_components))
    pairs = merge.choose_pairs(mixture.posterior, counts, grow.is_active(prior), n_pairs,
                               config.prior.colour_noise)
    return _merged(state, pairs, config), pairs.reshape(-1)


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
                          colour=merge.merge_rows(state.colour, pairs))


def _auto_room(state: MapState, xyz, ray, levels, config: Config
               ) -> tuple[MapState, np.ndarray]:
    """``components="auto"``: the count follows the data by births and merges.

    Births are :func:`vbgs.inference.grow.grow`'s new ground at a resolution the data
    set: the first frame fixes the cell side so that each level-0 cell holds about
    ``growth.auto_points`` of its points (the sensor's own sampling, whatever the
    scene's extent), and ground is not refined further (refinement spends a share of a
    budget there is none of). Every ``growth.auto_merge_every`` frames the neighbours
    whose merge raises the bound are merged (:func:`vbgs.inference.merge.bound_pairs`,
    the derivation in :mod:`vbgs.inference.merge`): the data decide where one component
    explains what two did. When the frame's new ground wants more slots than are empty
    the capacity grows to the next bucket (:mod:`vbgs.inference.capacity`: a compilation
    per bucket, not per frame); at ``config.max_components`` it stops growing, the state
    says so (``capped``) and the cheapest pairs are merged as under a fixed K."""
    g = config.growth
    merged = np.zeros(0, np.int64)
    if g.merge and state.n_frames and state.n_frames % g.auto_merge_every == 0:
        mixture = state.mixture
        pairs = merge.bound_pairs(mixture, grow.is_active(mixture.prior),
                                  config.prior.colour_noise)
        state, merged = _merged(state, pairs, config), pairs.reshape(-1)
    short = grow.shortfall(state.mixture, xyz, state.rule, ray=ray, levels=levels)
    k0 = state.mixture.prior.n_components
    if short > 0:
        k = capacity.bucket(k0 + short, AUTO_BUCKET, config.max_components)
        if k > k0:
            state = state._replace(
                mixture=capacity.widen(state.mixture, k, state.rule.cell, config.prior),
                evidence=capacity.widen_rows(state.evidence, k),
                colour=capacity.widen_rows(state.colour, k))
        if k0 + short > k:  # at the ceiling: make room as a fixed K does
            state, more = _make_room(state._replace(capped=True), xyz, ray, levels, config)
            merged = np.concatenate([merged, more])
    return state, merged


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


def _sync_stepper(state: MapState, slots: np.ndarray, config: Config) -> MapState:
    """The stepper for the state's reference: built on the first frame, grown (a new
    stepper sharing the compiled step) after the frame's growth filled ``slots``."""
    prior = state.mixture.prior
    if state.stepper is None or state.stepper.prior.n_components != prior.n_components:
        reach = None
        if state.growing and config.estep == "sparse":
            reach = grow.reach_of(state.rule, config.growth.reach_cells)
        step = Stepper(prior, assign=config.assign, config=config.prior, estep=config.estep,
                       n_candidates=config.candidates, grows=state.growing, reach=reach)
    elif len(slots):
        step = state.stepper.grow(prior, slots)
    else:
        return state
    return state._replace(stepper=step, geometry=mixture_geometry(prior))


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
