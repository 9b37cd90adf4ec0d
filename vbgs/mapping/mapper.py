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
   (:func:`vbgs.render.background.empty_pixels`), never in a hole of a surface;
4. one compiled conjugate update learns the points, with their noise along the rays
   when the depth is measured (:mod:`vbgs.mapping.measurement`;
   :class:`vbgs.inference.stepper.Stepper`;
   growth hands it the new rows without recompiling); points farther than
   ``growth.reach_cells`` cells from every component are left out and counted
   (``MapState.n_unlearned``);
5. under ``render.colour_rule == "fit"`` the frame's colour least-squares terms are
   added against the splats of the posterior that has just learned it
   (:mod:`vbgs.render.colour_fit`).

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
from vbgs.inference import expfam, grow, merge, model
from vbgs.inference.bound import BatchBound, batch_bound
from vbgs.inference.stepper import Stepper
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
    k = config.components
    mixture = None
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
    ([3] or None: black) is what the frame's pixels without a splat show; only the
    colour fit reads it (pixels without depth are not points)."""
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
                                   empty=empty_pixels(frame.depth, holes=not sensor.exact))
    before = state.mixture.posterior
    mixture, step = state.stepper(state.mixture, xyz, rgb, ray, reach, weight)
    n = len(xyz)
    if step.learned is not None:  # points beyond reach were left out
        xyz, rgb = xyz[step.learned], rgb[step.learned]
    state = state._replace(mixture=mixture, evidence=evidence, n_points=state.n_points + n,
                           n_unlearned=state.n_unlearned + n - len(xyz))
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
    k, g = config.components, config.growth
    if mixture is None:  # the first frame fixes the cell side
        rule = grow.calibrate(xyz, k, g.first_frame_share * k, refine=g.refine_share,
                              levels=g.levels, rate=g.max_new_share, footprint=footprint,
                              coarse=g.coarse_levels, coarse_from=g.coarse_from)
        mixture = _measured(grow.start_empty(xyz, k, rule.cell, config.prior), config)
    key, sub = jax.random.split(state.key)
    levels = grow.point_levels(rule, footprint)
    state, merged = _make_room(state._replace(mixture=mixture, rule=rule), xyz, ray, levels,
                               config)
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
    empty = grow.empty_prior(prior.n_components, prior.origin, rule.cell, config.prior,
                             prior.alpha.dtype)
    state = state._replace(mixture=merge.merge(mixture, pairs, empty),
                           evidence=merge.merge_rows(state.evidence, pairs),
                           colour=merge.merge_rows(state.colour, pairs))
    return state, pairs.reshape(-1)


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
    if state.stepper is None:
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
