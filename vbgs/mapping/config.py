"""The scene learner's hyperparameters: one frozen, nested :class:`Config`.

Every method constant of :mod:`vbgs.mapping` is a field here (or of the
:class:`vbgs.inference.model.PriorConfig` it holds), so a tuning command reaches any of
them by its dotted name (``growth.reach_cells``, ``evidence.pass_sigmas``,
``prior.cov_scale``; :func:`with_dotted`). The defaults are the named constants of the
modules that use them, each explained there; the values are said where they were chosen.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from vbgs.inference import grow
from vbgs.components import (AUTO_MERGE_EVERY, AUTO_POINTS, AUTO_REFINE_GAIN, AUTO_REFINE_SHAPE,
                             parse_components)
from vbgs.inference.candidates import default_candidates
from vbgs.inference.model import SURFACE_PRIOR, PriorConfig
from vbgs.mapping.change import (EXACT_DOUBT_OPACITY, FORGET_AFTER, RECOLOUR_REFERENCES,
                                 SHAPED_POINTS)
from vbgs.mapping.holes import HOLE_COLOUR_TOL, HOLE_RADIUS
from vbgs.mapping.budget import POINTS as BUDGET_POINTS, WEIGHTED as BUDGET_WEIGHTED
from vbgs.mapping.denoise import sensor_radius
from vbgs.render import colour_fit, opacity
from vbgs.render.splats import VBGS_BLUR, VBGS_COV_SCALE, VBGS_OPACITY
from vbgs.sensors import SENSOR_NAMES, WHITE_NOISE_SENSORS

ASSIGN = ("prior", "posterior")
ESTEP = ("dense", "sparse")
SEARCH = ("auto", "kdtree", "projective")
# search "auto": the projective search for frames of more than this many pixels, the
# KD-tree up to it. A frame's points run the KD-tree's host queries point by point, where
# projection bins the map once a frame on the device. The rule: the projective search
# where it scores within 0.1 dB of the KD-tree on validation views and takes less time:
# at 640 x 480 (results/tuning/search/, made by the commands in them) it does, and takes
# a third less time a frame. At fit-scene's 128 px it does not (0.31 dB under the KD-tree
# on the mean of object, room and walk, results/tuning/search/size128/): up to 320 x 240
# frames keep the KD-tree, whose candidates are every point's nearest means wherever they
# lie, where a tile lists a fixed number (far ground loses points).
PROJECTIVE_PIXELS = 320 * 240
OPACITY_RULES = ("evidence", "constant")
COLOUR_RULES = ("posterior", "fit")

# The share of the capacity K a growing map's first frame gets: it fixes the cell side of
# vbgs.inference.grow (the area the frame covers over this many cells). A tenth leaves
# nine tenths for the ground later frames show. Checked on validation views (rule: the
# best mean PSNR over the object, the room and the walk at fit-scene's defaults;
# results/tuning/first_frame_share/mean.md, made by the command in it, re-made at the code
# in its first line): a tenth is the best mean by about a dB over a fifth and more over a
# twentieth, though the room alone prefers a fifth.
FIRST_FRAME_SHARE = 0.1
# The share of the empty slots a frame may spend refining ground already covered (finer
# cells, vbgs.inference.grow.select); what is left stays for new ground in later frames.
REFINE_SHARE = 0.05
# Merging (vbgs.inference.merge) frees at least this share of K at a time, so that a
# stream meeting new ground every frame merges every few frames, not every frame (each
# round scores every component's neighbours). The rule: a larger share only where it
# scores at least as well on every validation table of results/tuning/merge_ahead/
# (exact depth at 20k and 50k, the Kinect at 128 px and at 640 x 480, the room at
# 640 x 480 with exact depth), made by the commands in them. 0.1 gains at 128 px and
# spaces the rounds out (the room at fit-scene's defaults: 9 rounds in 60 frames against
# 35, results/stream_rate/merge_ahead/), but loses under the Kinect at 640 x 480, where a
# round frees 10k slots of a 20-frame stream: 0.02 stays.
MERGE_AHEAD = 0.02
# Once the map has forgotten anything (its world is seen to change) and fewer slots are
# empty than refine_share of K, a frame's refinement may take every empty slot new ground
# leaves, merges paying for ground to come; True: the best mean on the changing scenes'
# validation views at seeds 0, 1 and 2 (results/tuning/changed_refine/mean.md and
# seed1/, seed2/, made by the commands in them).
CHANGED_REFINE = True
# New ground once the budget is spent: as many levels coarser as the ground met allows
# (mapper.ground_levels). The rule: the best validation PSNR on every stream the setting
# changes. One lap (object, room and walk at fit-scene's defaults) never reaches a level
# with "ground", so it is learned as with 0, to the bit; a fixed level costs it
# (results/tuning/spent_levels/exact/mean.md: 23.83 dB at 0, 23.73 at one level, 22.99 at
# two). On the 200-frame walk "ground" scores 21.69 against 21.49 at 0 and 21.54 at one
# level (walk_long/walk-long.md); the walks under the simulated Kinect and RealSense,
# which merge five to seven times K, 14.06 against 14.02 and 15.42 against 15.46
# (walk_kinect/, walk_realsense/).
SPENT_LEVELS = "ground"
# Colour read as evidence of change with exact depth, behind the colour gate
# (vbgs.mapping.change, "A colour gate"). The rule: the best mean validation PSNR over the
# changing scenes (object-change, room-change, walk-change) among the settings under which
# a static stream with exact depth is what it is with colour off, to the bit. Without a
# gate colour scores best (23.40 dB) but forgets the static object's rims; behind one, 4
# colour sigmas at a gate of 0.5% of the slots is best (23.30 dB, against 23.28 at 1% and
# 2%, where the walk's few changes no longer open it, and 23.19 at 2 sigmas;
# results/tuning/recolour_gate/mean.md), 4 sigmas also the best of 2 to 8 without one
# (results/tuning/recolour/). A static stream with exact depth forgets no component by
# depth, or a handful of thin posts (the 200-frame walk 3 of 20000, 0.015%): far below
# the gate. Under a measured sensor depth's own tails forget floaters by the hundred (the
# RealSense's static object 4% of its slots, as many as the changing room's removed
# furniture), so no gate tells a static world there: colour stays off (0).
EXACT_RECOLOUR_SIGMAS = 4.0
RECOLOUR_GATE = 0.005


def _switch(name: str, value) -> None:
    """Refuse a setting ``name`` (dotted) that is not a bool."""
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")


def _positive(owner: str, name: str, value, *, upper: float | None = None) -> None:
    ok = isinstance(value, (int, float)) and math.isfinite(value) and value > 0
    if not ok or (upper is not None and value > upper):
        bound = f" and at most {upper}" if upper is not None else ""
        raise ValueError(f"{owner}.{name} must be a positive number{bound}, got {value!r}")


@dataclass(frozen=True)
class GrowthConfig:
    """How a map that starts empty allocates components (:mod:`vbgs.inference.grow`).

    first_frame_share: share of K the first frame gets (fixes the cell side);
    refine_share: share of the empty slots a frame may spend on finer cells;
    changed_refine: once the map has forgotten components as gone
        (:mod:`vbgs.mapping.change`) and fewer slots are empty than ``refine_share`` of
        K, refinement may take every empty slot new ground leaves, as a fresh map's
        first frames would, merges paying for ground to come
        (``vbgs.mapping.mapper._refining``; not for ``components="auto"``, whose splits
        decide its refinement);
    levels: cell levels refinement may use (each half the side of the one before);
    max_new_share: the most components one frame may add, as a share of K;
    reach_cells: points farther than this many cells from every component are left
        out of the update (:func:`vbgs.inference.grow.reach_of`);
    coarse_levels: coarse cells (side ``cell * 2^j``, j at most this) for ground seen
        coarsely (:func:`vbgs.inference.grow.point_levels`; 0: one cell side everywhere);
    auto_points, auto_merge_every: ``components="auto"`` only (``mapper._auto_room``):
        first-frame points per level-0 cell (the resolution), frames between rounds of
        merges scored by the bound (0: none; at auto:MAX the budget merges still run);
    split, refine_gain, refine_footprints: ``components="auto"`` only: a point seeds a
        finer component where the log Bayes factor of a child, from every colour its cell
        has shown, exceeds ``refine_gain`` nats (the prior log odds against a split), in
        cells no finer than ``refine_footprints`` pixel footprints
        (:mod:`vbgs.mapping.splits`; ``split`` false: no refinement);
    refine_shape: ``components="auto"`` only: the split score adds the shape term, how
        much better a child's own plane explains its cell's points along their normal
        than the component that explains them now (:func:`vbgs.mapping.splits.
        surface_gain`: where a surface bends or ends);
    hole_radius, hole_colour_tol: measured depth only (``sensor`` not exact): a hole behind
        a depth edge or inside a surface takes the depth extrapolated from the nearest
        pixel within ``hole_radius`` px whose colour differs by at most ``hole_colour_tol``
        per channel (:mod:`vbgs.mapping.holes`; radius 0: holes stay holes);
    denoise_radius: noise independent between pixels only (``sensor.white``): each
        reading is replaced by the plane fitted to its surface's readings within this
        many px (:mod:`vbgs.mapping.denoise`; 0: read as measured; None: the sensor's
        own, ``denoise.SENSOR_RADII``: 1 for the Kinect, 3 for the RealSense; the
        radius a map uses is :attr:`Config.denoise_radius`);
    hold_seeds: a component's seed (its prior mean) holds its cell as its posterior mean
        does, so ground whose components' means moved out of it is not grown again;
    hold_paid: the cells where merged components stood stay held (a merge pays for the
        ground once; ``vbgs.mapping.mapper._paid``);
    spent_levels: once the budget is spent (a round of merges has made room), new ground
        takes cells this many levels coarser (side ``cell * 2^j`` more), so the ground a
        stream meets late costs fewer components and fewer merges of what it learned
        first (``vbgs.mapping.mapper._spent_levels``; 0: the same cells throughout;
        ``"ground"``: as many as the ground met so far allows,
        ``vbgs.mapping.mapper.ground_levels``).
    """

    first_frame_share: float = FIRST_FRAME_SHARE
    refine_share: float = REFINE_SHARE
    changed_refine: bool = CHANGED_REFINE
    levels: int = grow.LEVELS
    max_new_share: float = grow.MAX_NEW_SHARE
    reach_cells: float = grow.REACH_CELLS
    coarse_levels: int = grow.COARSE_LEVELS
    # merging on, coarse cells from 4x: the best mean validation PSNR over object, room
    # and walk, results/tuning/growth/mean.md
    merge: bool = True
    merge_ahead: float = MERGE_AHEAD
    # off. hold_paid: it lowers the mean of object, room and walk on validation views
    # (results/tuning/hold/mean.md). hold_seeds: the best of that mean, by less than a
    # tenth of a dB, and below it under the Kinect (results/tuning/hold_kinect/mean.md,
    # 23.61 against 23.66 dB): off.
    hold_paid: bool = False
    hold_seeds: bool = False
    spent_levels: int | str = SPENT_LEVELS
    coarse_from: float = grow.COARSE_FROM
    auto_points: float = AUTO_POINTS
    auto_merge_every: int = AUTO_MERGE_EVERY
    split: bool = True
    refine_gain: float = AUTO_REFINE_GAIN
    refine_footprints: float = grow.REFINE_FOOTPRINTS
    refine_shape: bool = AUTO_REFINE_SHAPE
    hole_radius: int = HOLE_RADIUS
    hole_colour_tol: float = HOLE_COLOUR_TOL
    denoise_radius: int | None = None

    def __post_init__(self):
        _positive("growth", "first_frame_share", self.first_frame_share, upper=1.0)
        if not isinstance(self.hole_radius, int) or self.hole_radius < 0:
            raise ValueError(f"growth.hole_radius must be an integer >= 0 (pixels; 0: holes "
                             f"stay holes), got {self.hole_radius!r}")
        _positive("growth", "hole_colour_tol", self.hole_colour_tol)
        if self.denoise_radius is not None and (
                not isinstance(self.denoise_radius, int) or isinstance(self.denoise_radius, bool)
                or self.denoise_radius < 0):
            raise ValueError(f"growth.denoise_radius must be an integer >= 0 (pixels; 0: the "
                             f"depth read as measured) or None (the sensor's own), got "
                             f"{self.denoise_radius!r}")
        if not (isinstance(self.auto_points, (int, float)) and math.isfinite(self.auto_points)
                and self.auto_points >= 1):
            raise ValueError(f"growth.auto_points must be a number >= 1 (a level-0 cell holds "
                             f"at least one of the first frame's points; fewer asks for more "
                             f"cells than there are points), got {self.auto_points!r}")
        if not isinstance(self.auto_merge_every, int) or self.auto_merge_every < 0:
            raise ValueError(f"growth.auto_merge_every must be an integer >= 0 (frames; 0: "
                             f"no merges scored by the bound), got {self.auto_merge_every!r}")
        if not (isinstance(self.refine_gain, (int, float)) and math.isfinite(self.refine_gain)
                and not isinstance(self.refine_gain, bool)):
            raise ValueError(f"growth.refine_gain must be a finite number (nats: the log "
                             f"Bayes factor a split must exceed), got {self.refine_gain!r}")
        _switch("growth.split", self.split)
        _switch("growth.refine_shape", self.refine_shape)
        _positive("growth", "refine_footprints", self.refine_footprints)
        _positive("growth", "max_new_share", self.max_new_share, upper=1.0)
        _positive("growth", "reach_cells", self.reach_cells)
        s = self.refine_share
        if not (isinstance(s, (int, float)) and not isinstance(s, bool) and 0 <= s <= 1):
            raise ValueError(f"growth.refine_share must be in [0, 1], got {s!r}")
        j = self.spent_levels
        if j != "ground" and (not isinstance(j, int) or isinstance(j, bool) or j < 0):
            raise ValueError(f"growth.spent_levels must be a whole number of cell levels >= 0 "
                             f"(0: new ground takes the same cells once the budget is "
                             f"spent) or \"ground\" (as many as the ground met allows), "
                             f"got {j!r}")
        if not isinstance(self.levels, int) or self.levels < 1:
            raise ValueError(f"growth.levels must be a positive integer, got {self.levels!r}")
        for name in ("merge", "hold_paid", "hold_seeds", "changed_refine"):
            _switch(f"growth.{name}", getattr(self, name))
        _positive("growth", "coarse_from", self.coarse_from)
        if not (isinstance(self.merge_ahead, (int, float)) and 0 <= self.merge_ahead < 0.5):
            raise ValueError(f"growth.merge_ahead must be in [0, 0.5), got {self.merge_ahead!r}")
        if not isinstance(self.coarse_levels, int) or self.coarse_levels < 0:
            raise ValueError(f"growth.coarse_levels must be an integer >= 0, got "
                             f"{self.coarse_levels!r}")


@dataclass(frozen=True)
class EvidenceConfig:
    """Opacity from the rays that hit or pass each component (:mod:`vbgs.render.opacity`).

    pass_sigmas: an observed depth within this many sigma (camera z) is a hit;
    prior_hits, prior_passes: the Beta prior's pseudo-counts of rays;
    forget_after: a growing map forgets a component its frames saw through this many
        times in a row with none hitting it (:mod:`vbgs.mapping.change`; 0: never);
    recolour_sigmas: a frame whose rays that hit a component show a mean colour farther
        than this many colour sigmas (``prior.colour_noise``) from what earlier frames'
        rays showed on it counts against it as a see-through does (a repainted surface;
        0: colour tells no change; None, the default: :data:`EXACT_RECOLOUR_SIGMAS` with
        exact depth behind the colour gate, 0 under a measured sensor,
        :meth:`Config.recolour_sigmas`; :mod:`vbgs.mapping.change` says why);
    recolour_reference: what a frame's colour is judged against (``RECOLOUR_REFERENCES``):
        ``"history"``, the mean of what earlier frames' rays showed, the tolerance
        ``recolour_sigmas`` colour sigmas; ``"posterior"``, the component's colour
        posterior, the tolerance ``recolour_sigmas`` times the distance expected where
        nothing changed (the model's colour noise, the posterior's own uncertainty and the
        spread of colour the frame's rays show on it: safe on static streams from 6,
        :mod:`vbgs.mapping.change`); ``"map"``, the history's test where the map as a
        whole, drawn at the frame's pose, and the component's own colour both fail to
        explain the pixels its rays read, beyond ``recolour_sigmas`` colour sigmas;
    recolour_gate: with colour read (``recolour_sigmas`` above 0), the share of the slots
        the frames' depth must have forgotten before a recoloured component is forgotten:
        colour then counts in a run of its own, apart from the see-throughs, and a world
        that never showed change by depth is never recoloured, so a static stream is what
        it is with colour off, to the bit (:mod:`vbgs.mapping.change`, "A colour gate";
        default :data:`RECOLOUR_GATE`; 0: no gate, colour counts in the see-throughs' run
        from the first frame);
    shaped_points: a component holding at least this many points is seen through when
        the rays pass beyond it along its own shape (the Gaussian taken along each ray),
        one with fewer when they pass beyond its extent along the camera axis
        (:mod:`vbgs.mapping.change`; 0, the default: every component; inf: none;
        exact depth only: a measured sensor's tails keep the extent's band);
    doubt_opacity: a run of frames that count against a component starts only where its
        expected opacity (its rays' hits against passes so far) is at least this: a
        component the rays pass about as often as they hit it (thinner than a pixel) is
        never judged gone (:mod:`vbgs.mapping.change`; 0: any component; None, the
        default: :data:`vbgs.mapping.change.EXACT_DOUBT_OPACITY` with exact depth, 0
        under a measured sensor, :meth:`Config.doubt_opacity`);
    through_background: under a measured sensor with a range (the Kinect, the RealSense),
        a frame's pixels that show the background (no depth, joined to the image's
        border: :func:`vbgs.render.background.empty_pixels`) count as seen through for
        the components within the sensor's range, as every pixel without depth does
        with exact depth (a surface standing there would have returned a depth); its
        holes never count (on, the default; off: no pixel without depth does;
        :mod:`vbgs.mapping.change` says what it changes).
    """

    pass_sigmas: float = opacity.PASS_SIGMAS
    prior_hits: float = opacity.PRIOR_HITS
    prior_passes: float = opacity.PRIOR_PASSES
    forget_after: int = FORGET_AFTER
    recolour_sigmas: float | None = None
    recolour_reference: str = "history"
    recolour_gate: float = RECOLOUR_GATE
    shaped_points: float = SHAPED_POINTS
    doubt_opacity: float | None = None
    # On. The rule is the best mean PSNR on the validation views of the changing and the
    # static object and room under the Kinect (results/tuning/through_background/mean.md),
    # where it leads on each scene; with exact depth or a depth network it changes nothing.
    through_background: bool = True

    def __post_init__(self):
        for name in ("pass_sigmas", "prior_hits", "prior_passes"):
            _positive("evidence", name, getattr(self, name))
        if not isinstance(self.forget_after, int) or isinstance(self.forget_after, bool) \
                or self.forget_after < 0:
            raise ValueError(f"evidence.forget_after must be a whole number of frames >= 0 "
                             f"(0: never forget), got {self.forget_after!r}")
        r = self.recolour_sigmas
        if r is not None and (isinstance(r, bool) or not isinstance(r, int | float)
                              or not 0 <= r < math.inf):
            raise ValueError(f"evidence.recolour_sigmas must be a number >= 0 (0: colour "
                             f"tells no change), got {r!r}")
        _choice("evidence.recolour_reference", self.recolour_reference, RECOLOUR_REFERENCES)
        g = self.recolour_gate
        if isinstance(g, bool) or not isinstance(g, int | float) or not 0 <= g < 1:
            raise ValueError(f"evidence.recolour_gate must be a share of the slots in [0, 1) "
                             f"(0: no gate), got {g!r}")
        p = self.shaped_points
        if isinstance(p, bool) or not isinstance(p, int | float) or not p >= 0:
            raise ValueError(f"evidence.shaped_points must be a number of points >= 0 "
                             f"(inf: never judged along the shape), got {p!r}")
        o = self.doubt_opacity
        if o is not None and (isinstance(o, bool) or not isinstance(o, int | float)
                              or not 0 <= o <= 1):
            raise ValueError(f"evidence.doubt_opacity must be an opacity in [0, 1] (0: any "
                             f"component may be doubted), got {o!r}")
        _switch("evidence.through_background", self.through_background)


@dataclass(frozen=True)
class SensorConfig:
    """How the depth was measured (:mod:`vbgs.mapping.measurement`, :mod:`vbgs.sensors`).

    model: a sensor of :data:`vbgs.sensors.SENSOR_NAMES` (``exact``: the depth is the
        surface's, a missing pixel shows nothing);
    level: its noise multiplier (1: the published model).
    """

    model: str = "exact"
    level: float = 1.0

    def __post_init__(self):
        _choice("sensor.model", self.model, SENSOR_NAMES)
        if not (isinstance(self.level, (int, float)) and math.isfinite(self.level)
                and self.level >= 0):
            raise ValueError(f"sensor.level must be a finite number >= 0, got {self.level!r}")

    @property
    def exact(self) -> bool:
        """The depth is the surface's: no noise, and a pixel without depth shows nothing.
        Any other sensor leaves holes in surfaces, at every level (its holes are physical,
        :mod:`vbgs.sensors.holes`): only :func:`vbgs.render.background.empty_pixels` are
        empty."""
        return self.model == "exact"

    @property
    def noisy(self) -> bool:
        """The depth values carry the sensor's noise (level > 0): each point's noise
        along its ray enters the update (:mod:`vbgs.mapping.measurement`)."""
        return self.model != "exact" and self.level > 0

    @property
    def white(self) -> bool:
        """The depth carries noise drawn independently at each pixel (an active sensor
        at level > 0): averaging a surface's neighbouring readings removes it
        (:mod:`vbgs.mapping.denoise`)."""
        return self.noisy and self.model in WHITE_NOISE_SENSORS


@dataclass(frozen=True)
class RenderConfig:
    """How the posterior becomes splats (:func:`vbgs.render.splats.from_posterior`).

    splat_scale: sigma multiplier of the expected covariance;
    splat_blur: pixel filter variance (px²) the splats are drawn with;
    opacity_rule: ``evidence`` (per component, :mod:`vbgs.render.opacity`) or ``constant``;
    opacity: the constant of ``opacity_rule="constant"``;
    colour_rule: ``posterior`` (colour means) or ``fit`` (least squares to the pixels,
        :mod:`vbgs.render.colour_fit`); colour_ridge: its pixels' worth of weight on
        the posterior colour.
    """

    splat_scale: float = VBGS_COV_SCALE
    splat_blur: float = VBGS_BLUR
    opacity_rule: str = "evidence"
    opacity: float = VBGS_OPACITY
    colour_rule: str = "posterior"
    colour_ridge: float = colour_fit.RIDGE

    def __post_init__(self):
        _choice("render.opacity_rule", self.opacity_rule, OPACITY_RULES)
        _choice("render.colour_rule", self.colour_rule, COLOUR_RULES)
        _positive("render", "splat_scale", self.splat_scale)
        _positive("render", "opacity", self.opacity, upper=1.0)
        _positive("render", "colour_ridge", self.colour_ridge)
        if not (isinstance(self.splat_blur, (int, float)) and 0 <= self.splat_blur < 10):
            raise ValueError(f"render.splat_blur must be a pixel filter variance in [0, 10) "
                             f"px², got {self.splat_blur!r}")


@dataclass(frozen=True)
class BudgetConfig:
    """A frame's point budget (:mod:`vbgs.mapping.budget`).

    points: the most points one frame gives (every ``s``-th pixel along each axis from a
        random offset); 0: every valid pixel; the default thins frames of more than 80k
        pixels (a 640 x 480 sensor's) to stride 2 (:data:`vbgs.mapping.budget.POINTS`);
    weighted: each kept point counts ``s^2`` (the statistics an unbiased estimate of the
        whole frame's) rather than 1 (the default: better on validation views);
    saturation: the most points a growing map learns per cell over the stream (points
        of cells already learned that often are skipped before any expensive work,
        :mod:`vbgs.mapping.saturation`); 0: no such limit.
    """

    points: int = BUDGET_POINTS
    weighted: bool = BUDGET_WEIGHTED
    saturation: int = 0

    def __post_init__(self):
        if not isinstance(self.points, int) or isinstance(self.points, bool) or self.points < 0:
            raise ValueError(f"budget.points must be an integer >= 0 (0: every point), got "
                             f"{self.points!r}")
        _switch("budget.weighted", self.weighted)
        if (not isinstance(self.saturation, int) or isinstance(self.saturation, bool)
                or self.saturation < 0):
            raise ValueError(f"budget.saturation must be an integer >= 0 (0: no limit), got "
                             f"{self.saturation!r}")


def _choice(name: str, value, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(choices)}; got {value!r}")


@dataclass(frozen=True)
class Config:
    """Everything the scene learner needs besides the data and the key.

    components: the capacity K (static shapes: a fixed number of slots), or ``"auto"`` /
        ``"auto:MAX"``: K chosen from the data (``mapper._auto_room``; slots grow in
        buckets, at most MAX; :func:`vbgs.components.parse_components`);
    assign: responsibilities under the ``prior`` (a stream equals one batch, in any
        order, when that reference is fixed: given to ``init``, not grown, not re-seeded)
        or the current ``posterior`` (order-dependent);
    estep: over all components (``dense``) or the ``candidates`` nearest (``sparse``);
    search: how a frame's points find their sparse candidates: the ``kdtree`` over the
        means (the reference), or by ``projective`` association, the map's components
        binned by where they fall in the frame (:mod:`vbgs.inference.projective`, on the
        device); ``auto`` (the default) takes the projective search for frames of more
        than :data:`PROJECTIVE_PIXELS` pixels (:func:`frame_search`); bare points without
        a camera always take the KD-tree;
    local_iters: under posterior assignment, the most E-steps of a batch's local
        coordinate ascent (:func:`vbgs.inference.model.local_cavi`: components grown for
        the batch start at their prior and a single E-step would score them so against
        neighbours fitted to earlier batches); 1, the default, is one E-step through the
        compiled stepper; ignored under prior assignment;
    reseed: before each batch the unused components of a fixed reference are moved onto
        its worst-explained points (:func:`vbgs.inference.reassign.reassign`, one more
        E-step per batch); the reference then changes from batch to batch, so the order
        matters even under prior assignment; not for a growing map (it grows its own);
    prior, growth, evidence, render, sensor, budget: the nested groups above.

    ``local_iters > 1`` (posterior assignment) and ``reseed`` learn through
    :func:`vbgs.inference.model.update`, the stepper's slow reference: every point at
    weight 1 and without noise along its ray, so neither takes a point budget or a
    measured depth.
    """

    components: int | str = 20000
    assign: str = "prior"
    estep: str = "sparse"
    candidates: int | None = None
    search: str = "auto"
    local_iters: int = 1
    reseed: bool = False
    prior: PriorConfig = SURFACE_PRIOR
    growth: GrowthConfig = field(default_factory=GrowthConfig)
    evidence: EvidenceConfig = field(default_factory=EvidenceConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    budget: BudgetConfig = field(default_factory=BudgetConfig)

    def __post_init__(self):
        parse_components(self.components)
        value = self.candidates
        if value is not None and (not isinstance(value, int) or isinstance(value, bool)
                                  or value < 1):
            raise ValueError(f"candidates must be a positive integer (None: the sensor's "
                             f"default), got {value!r}")
        _choice("assign", self.assign, ASSIGN)
        _choice("estep", self.estep, ESTEP)
        _choice("search", self.search, SEARCH)
        value = self.local_iters
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ValueError(f"local_iters must be a positive integer, got {value!r}")
        _switch("reseed", self.reseed)
        if self.slow_path and ((self.budget.points and self.budget.weighted)
                               or self.sensor.noisy):
            raise ValueError("local_iters > 1 under posterior assignment and reseed learn "
                             "every point at weight 1 without its noise: leave "
                             "budget.weighted off (or budget.points at 0) and the sensor "
                             "exact, or take one E-step per batch without reseed")
        if self.sensor.noisy and self.estep != "sparse":
            raise ValueError(f"a measured depth (sensor {self.sensor.model!r}) needs "
                             f"estep='sparse': its noise is modelled in the sparse E-step")

    @property
    def n_candidates(self) -> int:
        """Candidates per point: ``candidates``, or when None the sensor's default
        (:func:`vbgs.inference.candidates.default_candidates`: 8 with exact depth, 16
        under a measured sensor)."""
        return self.candidates or default_candidates(self.sensor.exact)

    @property
    def denoise_radius(self) -> int:
        """The window (pixels) a white-noise sensor's depth is averaged over:
        ``growth.denoise_radius``, or when None the sensor's own
        (:func:`vbgs.mapping.denoise.sensor_radius`: 1 for the Kinect, 3 for the
        RealSense)."""
        return sensor_radius(self.sensor.model, self.growth.denoise_radius)

    @property
    def recolour_sigmas(self) -> float:
        """``evidence.recolour_sigmas``, or when None the sensor's default
        (:data:`EXACT_RECOLOUR_SIGMAS` with exact depth, 0, colour off, under a measured
        sensor: :mod:`vbgs.mapping.change`, "A colour gate")."""
        r = self.evidence.recolour_sigmas
        return r if r is not None else (EXACT_RECOLOUR_SIGMAS if self.sensor.exact else 0.0)

    @property
    def doubt_opacity(self) -> float:
        """``evidence.doubt_opacity``, or when None the sensor's default
        (:data:`vbgs.mapping.change.EXACT_DOUBT_OPACITY` with exact depth, 0 under a
        measured sensor: :mod:`vbgs.mapping.change`, "Who may be doubted")."""
        o = self.evidence.doubt_opacity
        return o if o is not None else (EXACT_DOUBT_OPACITY if self.sensor.exact else 0.0)

    @property
    def slow_path(self) -> bool:
        """Batches are learned through :func:`vbgs.inference.model.update` rather than the
        compiled stepper: the reference is re-seeded before each, or each is solved by
        local coordinate ascent (``local_iters > 1`` under posterior assignment)."""
        return self.reseed or (self.assign == "posterior" and self.local_iters > 1)

    @property
    def auto(self) -> bool:
        """The component count is chosen from the data (``components="auto[:MAX]"``)."""
        return parse_components(self.components)[0]

    @property
    def max_components(self) -> int:
        """The capacity K, or under ``auto`` the most components it may use."""
        return parse_components(self.components)[1]


def dotted_names(config: Any = None, prefix: str = "") -> list[str]:
    """Every leaf field of a nested frozen config, by dotted name (``growth.levels``)."""
    config = Config() if config is None else config
    names = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            names += dotted_names(value, f"{prefix}{f.name}.")
        else:
            names.append(prefix + f.name)
    return names


def get_dotted(config: Any, name: str):
    """The value of the field ``name`` (dotted) of a nested config."""
    for part in name.split("."):
        if not dataclasses.is_dataclass(config) or part not in {
                f.name for f in dataclasses.fields(config)}:
            raise ValueError(f"{name!r} is not a setting; known: {', '.join(dotted_names())}")
        config = getattr(config, part)
    return config


def with_dotted(config: Any, name: str, value) -> Any:
    """``config`` with the field ``name`` (dotted: ``growth.reach_cells``) set to
    ``value``; the nested configs check the new value as they are rebuilt."""
    head, _, rest = name.partition(".")
    get_dotted(config, head)  # a known field, or a clear error
    if not rest:
        return dataclasses.replace(config, **{head: value})
    return dataclasses.replace(config, **{head: with_dotted(getattr(config, head), rest, value)})


def frame_search(search: str, camera) -> str:
    """The candidate search (``kdtree`` or ``projective``) a frame of ``camera`` (None:
    bare points) takes under ``Config.search`` = ``search``: ``auto`` resolved by the
    frame's size (:data:`PROJECTIVE_PIXELS`)."""
    if camera is None:
        return "kdtree"
    if search == "auto":
        big = int(camera.width) * int(camera.height) > PROJECTIVE_PIXELS
        return "projective" if big else "kdtree"
    return search
