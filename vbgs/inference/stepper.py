"""A compiled per-batch update for streams: what :func:`vbgs.inference.model.update` does, with the
work that does not change from batch to batch done once per stream.

Under prior assignment the assigning model is the fixed prior, so its E-step terms
(precisions, log-determinants, digammas), its KL to itself and the candidate lists of
the sparse E-step (:mod:`vbgs.inference.grid`) are built once, when the :class:`Stepper` is made.
Every batch is then one call of one compiled function (candidate search, E-step,
M-step, ELBO) on points padded to a size that only grows, so a stream of similar
frames compiles once; nothing is copied back to the host unless the caller asks.

The sparse E-step's candidates come from the device grid (:mod:`vbgs.inference.grid`, searched
inside the compiled function) or from a host KD-tree over the fixed means
(:mod:`vbgs.inference.candidates`, built once); ``search="auto"`` takes the KD-tree on a CPU, where
host and device share memory and the tree is faster, and the grid on an accelerator
unless building it would be costly (:data:`vbgs.inference.grid.MAX_BUILD_COST`).

A stream whose reference grows (:mod:`vbgs.inference.grow` fills empty slots of the fixed
capacity K) keeps its stepper: :meth:`Stepper.grow` recomputes the terms of the filled
rows only (padded to a power of two, so a few small functions compile per stream) and
shifts every other row's ``E[log pi_k]`` by the change of ``psi(sum_k alpha_k)``; the
terms keep their ``[K, ...]`` shapes, so the compiled step is not recompiled. Such a
stepper is built with ``grows=True`` and searches candidates with the host KD-tree
(rebuilt on growth): the grid's layout is a static argument planned from the means,
and re-planning it would recompile the step.

Under posterior assignment the terms are recomputed inside the compiled function from
the current posterior and the candidates come from a KD-tree over the current means,
rebuilt every batch, because the means move.

The slow references are :func:`vbgs.inference.model.update` (dense, or sparse with the KD-tree);
tests hold the stepper equal to them.
"""

from __future__ import annotations

import copy
from functools import partial
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import digamma

from vbgs.inference import candidates, expfam, frame_tiles, grid, grow, model, projective
from vbgs.inference.model import Assign, EStep, Info, Mixture, PriorConfig, State

Search = Literal["auto", "grid", "kdtree", "projective"]
SEARCHES = ("auto", "grid", "kdtree", "projective")


class StepInfo(NamedTuple):
    """:class:`vbgs.inference.model.Info` of a stepped batch, and which points it learned."""

    elbo: jnp.ndarray  # scalar
    point_loglik: jnp.ndarray  # [size] padded: the first n entries are the batch's
    learned: np.ndarray | None  # [n] bool: within reach (None: no reach, every point)


# Headroom left when the padded size grows (see Stepper.padded_size).
GROWTH = 1.25
# A tiled frame's points that no tile lists a component within reach for are searched
# again in a KD-tree over the reference's means (Stepper._missed) when they are more than
# this share of the frame: the tree over every mean costs a frame some 20 ms at 100k
# components, far more than a few points can add. The room at 640 x 480 under the Kinect
# misses 1e-5 of its points (none of them within reach of any mean), the walk 3e-2 (the
# far ground, learned from the tree's nearest: results/tuning/search/).
MISSED_SHARE = 1e-3
# The smallest padded size of a stepper whose padding follows its batches (a smaller
# one would only add compilations for batches that cost little either way).
FOLLOW_MIN = 4096


class StepConfig(NamedTuple):
    """Static settings of the compiled step (hashable)."""

    assign: str
    estep: str
    colour_noise: float
    chunk: int
    grid: grid.GridSpec | None  # set when the compiled step searches candidates itself
    partial_lists: bool = False  # candidate lists may hold -1 (the projective search)


class Fixed(NamedTuple):
    """Arrays built once per stream under prior assignment (None otherwise); arguments
    of the compiled step, so new values of the same shapes (growth) do not recompile it."""

    reference: object  # [k, F] feature weights (dense) or model.Terms (sparse)
    kl: jnp.ndarray  # KL(prior || prior) = 0 exactly (computing it would add only rounding)
    lists: grid.CellLists | None


# Rows recomputed on growth go in blocks of this many (the last padded), so the row
# update compiles once per stream (each block size would compile it again, ~3 s).
ROW_BLOCK = 512


def _reference(q: Mixture, estep: str, colour_noise: float, alpha_total=None):
    if estep == "dense":
        return model.log_joint_weights(q, colour_noise, alpha_total)
    return model.component_terms(q, colour_noise, alpha_total)


@partial(jax.jit, static_argnames=("estep", "colour_noise"))
def _prior_terms(prior: Mixture, estep: str, colour_noise: float):
    """The prior's E-step terms, compiled as one function (eager, their many small ops
    would each compile)."""
    return _reference(prior, estep, colour_noise)


def _take_rows(q: Mixture, rows) -> Mixture:
    """The components ``rows [m]`` of ``q`` (the origin is shared)."""
    take = partial(jax.tree.map, lambda a: a[rows])
    return Mixture(take(q.space), take(q.colour), q.alpha[rows], q.origin)


def _grown_terms(reference, old_alpha, prior: Mixture, rows, estep: str, colour_noise: float):
    """The E-step terms of ``prior`` from those of a reference with concentrations
    ``old_alpha [k]`` that differs from it only in ``rows [m]`` (repeats allowed).

    The rows are recomputed; every other row keeps its terms except ``E[log pi_k] =
    psi(alpha_k) - psi(sum alpha)``, which moves by ``psi(sum old_alpha) -
    psi(sum alpha)`` (the constant of :class:`vbgs.inference.model.Terms`, the last column of the
    dense feature weights)."""
    total = prior.alpha.sum()
    shift = digamma(old_alpha.sum()) - digamma(total)
    fresh = _reference(_take_rows(prior, rows), estep, colour_noise, total)
    if estep == "dense":  # [k, F]
        return reference.at[:, -1].add(shift).at[rows].set(fresh)
    shifted = reference._replace(const=reference.const + shift)
    return jax.tree.map(lambda a, f: a.at[rows].set(f), shifted, fresh)


_GROWN = dict(static_argnames=("estep", "colour_noise"))
# The first block's terms are new arrays (the stepper that grows keeps its own); the
# later blocks' update them in place (donated: a [k, ...] copy a block saved, ~1 ms of
# CPU each at k = 100k; a frame of new ground fills tens of blocks).
_grown_first = jax.jit(_grown_terms, **_GROWN)
_grown_again = jax.jit(_grown_terms, donate_argnums=0, **_GROWN)


def row_blocks(rows) -> list[np.ndarray]:
    """``rows [m]`` in blocks of :data:`ROW_BLOCK`, the last padded by repeating its first
    entry (setting a row twice to the same value is harmless); none when m = 0."""
    rows = np.asarray(rows, np.int32).reshape(-1)
    blocks = [rows[i:i + ROW_BLOCK] for i in range(0, len(rows), ROW_BLOCK)]
    return [np.concatenate([b, np.full(ROW_BLOCK - len(b), b[0], np.int32)]) for b in blocks]


def _assigning(state: State, fixed: Fixed | None, config: StepConfig):
    """The assigning model's E-step terms and its KL to the prior (0 under prior
    assignment, where both were built once)."""
    if config.assign == "prior":
        return fixed.reference, fixed.kl
    q = state.posterior
    return (_reference(q, config.estep, config.colour_noise),
            model.kl(q, state.prior, config.colour_noise))


@partial(jax.jit, static_argnames=("config",))
def _step(state: State, x, c, w, fixed: Fixed | None, cand, config: StepConfig, ray=None,
          n_valid=None):
    """One batch: candidates (prior, sparse), E-step, statistics, M-step and ELBO.
    x ``[n, d]`` centred, c ``[n, 3]``, w ``[n]`` (0 for padding); the batch's real points
    are the first ``n_valid`` (a traced scalar: chunks of padding alone are skipped)."""
    reference, kl = _assigning(state, fixed, config)
    if config.grid is not None:
        cand = grid.search(fixed.lists, state.prior.space.mean, x, w, config.grid)
    batch, lse = model.e_step_with(reference, x, c, w, config.colour_noise, config.chunk,
                                   cand if config.estep == "sparse" else None, ray,
                                   config.partial_lists, n_valid)
    stats = expfam.add_stats(state.stats, batch)
    elbo = jnp.sum(lse * w) - kl
    # the prior is reattached by the caller (see model._update: passing an input through
    # next to the ELBO reduction made XLA:CPU hang)
    return model.m_step(state.prior, stats), stats, Info(elbo, lse)


@jax.jit
def _with_missed(info: Info, more: Info, at, kl) -> Info:
    """A tiled frame's ``info`` with its missed points' step ``more`` added: the ELBO
    summed (the KL ``kl`` counted once) and their point log-likelihoods put at their
    entries ``at [m]`` (past the end: padding, dropped)."""
    return Info(info.elbo + more.elbo + kl,
                info.point_loglik.at[at].set(more.point_loglik, mode="drop"))


@partial(jax.jit, static_argnames=("config", "tiling"))
def _tile_step(state: State, x, c, w, pixel, fixed: Fixed | None, config: StepConfig,
               tiling: projective.Tiling, v: projective.View, limit, ray=None):
    """:func:`_step` for a frame's points, one a pixel (``pixel [n]`` their flat pixel
    indices, -1: padding), by the projective search's tiles
    (:mod:`vbgs.inference.frame_tiles`): each tile's candidates found and its points scored
    against them at once. ``limit [n]``: each point's reach (inf: none). Returns
    :func:`_step`'s statistics and info, and which points were learned (within reach of
    a candidate), ``[n]`` bool; not the M-step, which the caller makes once, after the
    points the tiles missed (:meth:`Stepper._missed`: a second step over every
    component would make it again, 3 ms at 100k)."""
    reference, kl = _assigning(state, fixed, config)
    q = state.prior if config.assign == "prior" else state.posterior
    where = frame_tiles.layout(pixel, tiling)
    xg, cg, wg, limit = (frame_tiles.gridded(a, where) for a in (x, c, w, limit))
    seen, pool = projective.tile_pool(q.space.mean, q.alpha > grow.ACTIVE_ALPHA, v, tiling)
    depth = projective.project(v, xg.reshape(-1, 3)).z.reshape(wg.shape)
    n_tiles = tiling.tiles_x * tiling.tiles_y
    cand = projective.tile_candidates(pool, seen, v.intrinsics[0], v.intrinsics[1],
                                      frame_tiles.tile_depths(depth, wg)[:n_tiles], tiling)
    cand = jnp.pad(cand, ((0, where.tiles - n_tiles), (0, 0)), constant_values=-1)
    d2 = frame_tiles.nearest_distance(q.space.mean, xg, cand)
    within = jnp.isfinite(d2) & (d2 <= limit * limit)  # none listed: not learned
    wg = jnp.where(within, wg, 0.0)
    rays = None if ray is None else frame_tiles.gridded(ray, where)
    batch, lse = frame_tiles.e_step(reference, xg, cg, wg, cand, config.colour_noise, rays)
    stats = expfam.add_stats(state.stats, batch)
    elbo = jnp.sum(lse * wg) - kl
    info = Info(elbo, frame_tiles.pointwise(lse, where))
    return stats, info, frame_tiles.pointwise(within, where)


class Stepper:
    """``stepper(state, xyz, rgb) -> (state, info)``: :func:`vbgs.inference.model.update` for a
    stream from ``prior``, compiled once per padded size (see the module docstring).

    ``info.point_loglik`` stays on the device at the padded size: its first ``n``
    entries belong to the batch's ``n`` points (slicing it per batch would compile a
    slice per point count).

    ``max_points``: the most points a batch will hold, if known; batches are padded to
    a size that only grows (the first batch's bucket, or ``max_points``'s), so a stream
    of similar frames compiles one function.

    ``grows``: the reference will grow (:meth:`grow`); candidates then come from the
    host KD-tree (see the module docstring).

    ``follow``: batches are padded to the power of two that holds them, smaller ones
    too (:meth:`padded_size`), for streams whose batches shrink as the map learns.

    ``reach``: points farther than this from every mean of the assigning model (world
    units) are left out of the update (weight 0). No component
    explains them, and responsibilities, which sum to one whatever the distance, would
    otherwise hand them to the nearest components and stretch those across the gap into
    needles (a stream whose budget of components has run out). Sparse E-step with the
    KD-tree only (its query gives the distance for free). ``info.learned``: the batch's
    points within reach, ``[n]`` bool on the host (None without ``reach``).

    A stepper is not changed by a call or by growth (:meth:`grow` returns a new one that
    shares the compiled step); only its padded size, a cache of the compiled shapes, grows.
    """

    def __init__(self, prior: Mixture, *, assign: Assign = "prior",
                 config: PriorConfig = PriorConfig(), estep: EStep = "dense",
                 n_candidates: int = candidates.DEFAULT_CANDIDATES,
                 max_points: int | None = None, search: Search = "auto",
                 grows: bool = False, reach: float | None = None, follow: bool = False,
                 spacing: float | None = None):
        if assign not in ("prior", "posterior"):
            raise ValueError(f"unknown assignment mode {assign!r}: use 'prior' or 'posterior'")
        if estep not in ("dense", "sparse"):
            raise ValueError(f"unknown E-step {estep!r}: use 'dense' or 'sparse'")
        self.prior, self.assign, self.estep = prior, assign, estep
        self.colour_noise = float(config.colour_noise)
        self.n_candidates = int(min(n_candidates, prior.n_components))
        if self.n_candidates < 1:
            raise ValueError(f"n_candidates must be at least 1, got {n_candidates}")
        if search not in SEARCHES:
            raise ValueError(f"unknown candidate search {search!r}: use one of "
                             f"{', '.join(SEARCHES)}")
        projecting = search == "projective"
        if projecting and (estep != "sparse" or prior.dim != 3 or not spacing or spacing <= 0):
            raise ValueError("the projective search gives a frame's 3-D points their "
                             "candidates: it needs estep='sparse', a 3-D model and the "
                             f"components' spacing (a positive length), got estep={estep!r}, "
                             f"{prior.dim}-D, spacing={spacing!r}")
        if grows and search == "grid":
            raise ValueError("a growing reference cannot use the grid search (its layout is "
                             "planned from the means): use search='kdtree' or 'auto'")
        # the grid is built once, so it serves only a fixed assigning model; on a CPU the
        # host KD-tree reads the device's own memory (the grid is not even planned)
        fixed_sparse = assign == "prior" and estep == "sparse" and not grows
        if not projecting and (not fixed_sparse or (search == "auto"
                                                    and jax.default_backend() == "cpu")):
            search = "kdtree"
        spec = grid.plan(prior.space.mean, self.n_candidates) \
            if search in ("auto", "grid") else None
        if search == "auto":
            cheap = grid.build_cost(prior.space.mean, spec) <= grid.MAX_BUILD_COST
            search = "grid" if cheap else "kdtree"
        self.search = search
        self.spec, self.fixed, self._tree = None, None, None
        if assign == "prior":
            lists = None
            if estep == "sparse" and self.search == "grid":
                self.spec = spec
                lists = grid.build(prior.space.mean, self.spec)
            elif estep == "sparse" and not projecting:
                self._tree = candidates.means_tree(prior.space.mean)
            self.fixed = Fixed(_prior_terms(prior, estep, self.colour_noise),
                               jnp.zeros((), prior.alpha.dtype), lists)
        self.size = model.bucket_size(max_points) if max_points else 0
        self.follow = bool(follow)
        self._origin = np.asarray(prior.origin)
        if reach is not None and (self.estep != "sparse" or self.spec is not None
                                  or not reach > 0):
            raise ValueError(f"reach={reach!r} needs a positive distance, the sparse E-step "
                             "and the KD-tree search (estep='sparse', search='kdtree')")
        self.reach = reach
        self.spacing = spacing
        self.tiling: projective.Tiling | None = None  # fixed by the first frame
        self._spare = FOLLOW_MIN  # the padded size of a tiled frame's missed points
        self._missing = False  # the last tiled frame missed points (Stepper._missed)

    def grow(self, prior: Mixture, rows) -> Stepper:
        """A stepper for the grown reference ``prior``, which differs from this one's only
        in the components ``rows [m]`` (the slots :func:`vbgs.inference.grow.grow` filled):
        their terms are recomputed, the other rows' ``E[log pi_k]`` shifted
        (:func:`_grown_terms`), the KD-tree rebuilt; the compiled step is reused and this
        stepper is left as it was."""
        if self.spec is not None:
            raise ValueError("this stepper searches a grid planned from the means: build it "
                             "with grows=True to let its reference grow")
        if prior.n_components != self.prior.n_components or prior.dim != self.prior.dim:
            raise ValueError(f"the grown reference has {prior.n_components} {prior.dim}-D "
                             f"components, the stepper {self.prior.n_components} "
                             f"{self.prior.dim}-D ones: growth fills slots, it adds none")
        grown = copy.copy(self)
        blocks = row_blocks(rows)
        if self.fixed is not None and blocks:
            reference, old_alpha = self.fixed.reference, self.prior.alpha
            for i, block in enumerate(blocks):  # after the first the alpha sum is the new one
                update = _grown_again if i else _grown_first
                reference = update(reference, old_alpha, prior, jax.device_put(block),
                                   self.estep, self.colour_noise)
                old_alpha = prior.alpha
            grown.fixed = self.fixed._replace(reference=reference)
            if self._tree is not None:  # the projective search's is built when needed
                grown._tree = (None if self.search == "projective"
                               else candidates.means_tree(prior.space.mean))
        grown.prior = prior
        return grown

    def padded_size(self, n: int) -> int:
        """The size batches of ``n`` points are padded to: it only grows, and when it
        does it leaves :data:`GROWTH` headroom, so frames of a stream that vary in size
        a little share one compiled step. A stepper built with ``follow=True`` pads to
        the power of two that holds ``n`` instead (at least :data:`FOLLOW_MIN`): a
        stream whose batches shrink (points already explained skipped,
        :mod:`vbgs.mapping.saturation`) pays for the points it has, at one compilation
        per octave of batch size rather than one per batch."""
        if self.follow:
            return max(FOLLOW_MIN, 1 << (max(n, 1) - 1).bit_length())
        if n > self.size:
            self.size = model.bucket_size(int(n * GROWTH))
        return self.size

    def _chunk(self, size: int) -> int:
        if self.estep == "dense":
            return model.chunk_size(size, self.prior.n_components)
        d = self.prior.dim
        return model.chunk_size(size, self.n_candidates * (d * d + d + 4))

    def __call__(self, state: State, xyz, rgb, ray=None, reach=None, weight=None,
                 camera=None, pixel=None) -> tuple[State, StepInfo]:
        """Learn the batch ``xyz [n, d]``, ``rgb [n, 3]``; ``ray [n, d]``: measured
        points' noise along their rays (sparse E-step; :func:`vbgs.inference.model.update`);
        ``reach [n]``: each point's own reach, in place of the stepper's (a point seen
        coarsely reaches as far as the coarse components it may fall to); ``weight [n]``:
        each point's weight in the statistics (a thinned frame's, :mod:`vbgs.mapping.budget`;
        None: 1); ``camera``: the frame the points were measured in
        (:class:`vbgs.render.camera.Camera`), which the projective search reads (without
        one it searches a KD-tree over the means); ``pixel [n]``: with a camera, the flat
        (row-major) pixel each point was seen at, one point a pixel: the projective search
        then learns the frame by its tiles (:mod:`vbgs.inference.frame_tiles`)."""
        xyz, rgb = model.check_points_host(xyz, rgb)
        if xyz.shape[1] != self.prior.dim:
            raise ValueError(f"points are {xyz.shape[1]}-D but the model is {self.prior.dim}-D")
        size = self.padded_size(xyz.shape[0])
        x, c, w = model.padded_batch(xyz, rgb, self._origin, size, self.prior.alpha.dtype)
        if weight is not None:
            w[:xyz.shape[0]] = weight
        cand, learned, partial_lists = None, None, False
        if self.search == "projective" and camera is not None and pixel is not None:
            return self._by_tiles(state, x, c, w, xyz.shape[0], ray, reach, camera, pixel)
        if self.search == "projective" and camera is not None:
            cand, w, learned = self._project(state, x, w, xyz.shape[0], reach, camera)
            partial_lists = True
        elif self.estep == "sparse" and self.spec is None:
            n = xyz.shape[0]
            tree = self._tree or candidates.means_tree(state.posterior.space.mean)
            cand = np.zeros((size, self.n_candidates), np.int32)  # padding: weight 0
            nearest, cand[:n] = candidates.query_with_distance(tree, x[:n], self.n_candidates)
            if self.reach is not None:
                learned = nearest <= (self.reach if reach is None else np.asarray(reach))
                w[:n][~learned] = 0.0
        config = StepConfig(self.assign, self.estep, self.colour_noise, self._chunk(size),
                            self.spec, partial_lists)
        if ray is not None and self.estep != "sparse":
            raise ValueError("measurement noise (ray) needs the sparse E-step: estep='sparse'")
        rays = model.padded_rays(ray, xyz.shape[0], size, x.dtype)
        posterior, stats, info = _step(state, x, c, w, self.fixed, cand, config, rays,
                                       np.int32(xyz.shape[0]))
        if learned is not None:
            learned = np.asarray(learned)[:xyz.shape[0]]  # after the step is dispatched
        return state._replace(posterior=posterior, stats=stats), StepInfo(*info, learned)

    def _by_tiles(self, state: State, x, c, w, n: int, ray, reach, camera, pixel
                  ) -> tuple[State, StepInfo]:
        """:meth:`__call__` for a frame's points with their pixels: :func:`_tile_step`."""
        pixel = np.asarray(pixel).reshape(-1)
        if pixel.shape[0] != n or (n and (pixel.min() < 0 or
                                          pixel.max() >= camera.width * camera.height)):
            raise ValueError(f"pixel must give each of the {n} points its flat pixel index "
                             f"in the {camera.width} x {camera.height} frame")
        size = len(x)
        first = self.tiling is None
        self._fix_tiling(x, n, camera)
        flat = np.full(size, -1, np.int32)
        flat[:n] = pixel
        limit = np.full(size, np.inf, x.dtype)
        reaching = reach is not None or self.reach is not None
        if reaching:
            limit[:n] = self.reach if reach is None else np.asarray(reach, x.dtype)
        config = StepConfig(self.assign, self.estep, self.colour_noise, self._chunk(size),
                            None, True)
        rays = model.padded_rays(ray, n, size, x.dtype)
        stats, info, within = _tile_step(
            state, x, c, w, flat, self.fixed, config, self.tiling,
            projective.view(camera, self._origin, x.dtype), limit, rays)
        if self._missing and self._tree is None:  # on the host while the device steps
            self._tree = candidates.means_tree(self.prior.space.mean)
        within = np.asarray(within)[:n]
        stepped = state._replace(stats=stats)  # its posterior: the M-step below
        if first and self.assign == "prior":  # compiled with the first frame, unused
            _, more, at = self._missed_step(stepped, x, c, w, rays, np.zeros(0, np.int64),
                                            None)
            _with_missed(info, more, at, self.fixed.kl)
        self._missing = self.assign == "prior" and (~within).sum() > MISSED_SHARE * n
        if self._missing:
            stepped, info, within = self._missed(stepped, info, within, x, c, w, rays, limit)
        if stepped.stats is stats:  # the tiles' statistics alone: no missed step made it
            stepped = stepped._replace(posterior=grow._m_step(stepped.prior, stats))
        return stepped, StepInfo(*info, within if reaching else None)

    def _missed(self, state: State, info: Info, within: np.ndarray, x, c, w, rays, limit
                ) -> tuple[State, Info, np.ndarray]:
        """The points of a tiled frame whose tiles listed no component within their reach
        (``within [n]`` False; more than :data:`MISSED_SHARE` of them) searched again in
        a KD-tree over the reference's means and learned where it finds one within
        reach: a tile lists a fixed number of components, so far ground, where one tile
        spans many spacings, loses points that the KD-tree's nearest means would take
        (the walk at 640 x 480: 3% of its points). Prior assignment only: the missed
        points are scored against the same fixed reference, so the frame's statistics are
        those of one pass with these candidates (the candidate rule still reads only the
        prior and the frame).
        Returns the state with them added (:meth:`_missed_step`), the info (ELBO summed,
        their point log-likelihoods in place) and the points learned now."""
        missed, cand = self._nearest_means(x, np.flatnonzero(~within), limit)
        if len(missed) == 0:
            return state, info, within
        state, more, at = self._missed_step(state, x, c, w, rays, missed, cand)
        within = within.copy()
        within[missed] = True
        return state, _with_missed(info, more, at, self.fixed.kl), within

    def _missed_step(self, state: State, x, c, w, rays, missed: np.ndarray, cand
                     ) -> tuple[State, Info, np.ndarray]:
        """:meth:`_missed`'s step: the points ``x[missed]`` with their candidates ``cand
        [m, C]`` learned against the fixed reference, in a batch padded to the stepper's
        spare size (:data:`FOLLOW_MIN`, doubled when a frame misses more: one compilation
        per stream, made with the first frame, so that no frame of a stream waits for
        one). Returns the state, the step's info and each padded entry's point ``[size]``
        (``len(x)``: padding)."""
        m = len(missed)
        if m > self._spare:
            self._spare = 1 << (m - 1).bit_length()
        at = np.full(self._spare, len(x), np.int32)  # padding: past the end, dropped
        at[:m] = missed
        take = np.minimum(at, len(x) - 1)
        w2 = np.where(at < len(x), w[take], 0.0).astype(w.dtype)
        cand2 = np.zeros((self._spare, self.n_candidates), np.int32)
        if m:
            cand2[:m] = cand
        config = StepConfig(self.assign, self.estep, self.colour_noise,
                            self._chunk(self._spare), None, False)
        posterior, stats, more = _step(state, x[take], c[take], w2, self.fixed, cand2,
                                       config, None if rays is None else rays[take],
                                       np.int32(m))
        return state._replace(posterior=posterior, stats=stats), more, at

    def _nearest_means(self, x: np.ndarray, missed: np.ndarray, limit: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Of the points ``x[missed]`` that the projective search listed no component
        for, those whose nearest mean of the reference (a KD-tree over them) lies within
        their reach ``limit[missed]``, and their candidates ``[m, C]``."""
        if self._tree is None:  # kept while the reference is (until it grows)
            self._tree = candidates.means_tree(self.prior.space.mean)
        nearest, cand = candidates.query_with_distance(self._tree, x[missed],
                                                       self.n_candidates)
        near = nearest <= limit[missed]
        return missed[near], cand[near]

    def _fix_tiling(self, x: np.ndarray, n: int, camera) -> None:
        """The projective tiling, fixed by the first frame (its median depth) and
        following the frame's size."""
        if self.tiling is None:
            rot_t, shift = projective.world_to_camera(camera, self._origin)
            depth = np.asarray(x[:n], np.float64) @ rot_t[2] + shift[2]
            self.tiling = projective.plan(camera, self.spacing, float(np.median(depth)),
                                          self.n_candidates)
        elif (self.tiling.width, self.tiling.height) != (camera.width, camera.height):
            self.tiling = self.tiling._replace(width=int(camera.width),
                                               height=int(camera.height))

    def _project(self, state: State, x: np.ndarray, w: np.ndarray, n: int, reach,
                 camera) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray | None]:
        """The projective search (:mod:`vbgs.inference.projective`) of the padded centred
        points ``x [size, 3]`` seen by ``camera``: candidates ``[size, C]``, the weights
        with points beyond reach (or with no component listed near them) at 0, and which
        points are within reach (``[size]``; None without a reach). Under prior
        assignment the points listed nothing within reach (more than
        :data:`MISSED_SHARE` of them) take the KD-tree's nearest means where they are
        within it (:meth:`_missed`'s rule). The tiling is fixed by the
        first frame (its median depth)."""
        q = self.prior if self.assign == "prior" else state.posterior
        self._fix_tiling(x, n, camera)
        v = projective.view(camera, self._origin, x.dtype)
        active = q.alpha > grow.ACTIVE_ALPHA  # grow.is_active on the device: empty slots out
        cand, d2 = projective.search(q.space.mean, active, v, x, w, self.tiling)
        reaching = self.reach is not None or reach is not None
        limit = np.full(len(x), np.inf, x.dtype)
        if reaching:
            limit[:n] = self.reach if reach is None else np.asarray(reach, x.dtype)
        # a point with no component listed (d2 inf) is never learned, reach or none
        within = jnp.isfinite(d2) & (d2 <= jnp.asarray(limit) ** 2)
        if self.assign == "prior":  # the missed that the KD-tree finds, as _missed
            within = np.asarray(within).copy()
            missed = np.flatnonzero(~within[:n])
            if len(missed) > MISSED_SHARE * n:
                missed, rows = self._nearest_means(x, missed, limit)
                cand = np.array(cand)  # a list's spare entries -1, as the search's
                cand[missed] = -1
                cand[missed, :rows.shape[1]], within[missed] = rows, True
        return cand, jnp.where(within, w, 0.0), within if reaching else None

