"""The components setting: a fixed capacity K, or ``auto`` (the count chosen from the data).

Plain Python (no JAX, outside :mod:`vbgs.mapping`, whose package imports JAX): the
command line and the sweep's config check read it before
anything heavy is imported. What ``auto`` does is in :mod:`vbgs.mapping.mapper`
(``_auto_room``), :mod:`vbgs.inference.grow` (births on new ground at the first frame's
resolution, children in finer cells), :mod:`vbgs.mapping.splits` (where a child earns
its place: its Bayes factor from the colours its cell has shown), :mod:`vbgs.inference.merge`
(merges scored by the bound, off by default) and :mod:`vbgs.inference.capacity` (slots
grown in buckets).
"""

from __future__ import annotations

# components = "auto": the capacity grows in slots of these sizes, AUTO_BUCKET x 2^j
# (vbgs.inference.capacity), so a stream compiles its update once per bucket, not per frame.
AUTO_BUCKET = 4096
# The most components "auto" may use without ":MAX" (a memory ceiling: a bucket size).
AUTO_MAX_COMPONENTS = 131072
# "auto": first-frame points per level-0 cell (the resolution, in the sensor's own
# samples, that fixes the cell side in place of a share of K: mapper._auto_room). Rule:
# the best mean validation PSNR over object, room and walk, by `python -m experiments.run
# tune --scene object room walk --components auto --frames 60 --size 128 --grid
# growth.auto_points=2,4,8 --out results/tuning/components` (results/tuning/components/
# mean.md, its code version in its first line): 4 the best.
AUTO_POINTS = 4.0
# "auto": frames between two rounds of merges scored by the bound (vbgs.inference.merge.
# bound_pairs); 0: none (at auto:MAX the budget's merges still make room). Off: on
# validation views the merges the bound allows cost every scene's picture (the bound
# scores points, not pictures); the figures are in docs/validation.md ("AUTO_MERGE_EVERY").
AUTO_MERGE_EVERY = 0
# "auto": the split rule (vbgs.mapping.splits, derived there): a child in a finer cell
# when its log Bayes factor, the colour evidence of every point its cell has shown less
# the Occam factors of all its parameters (from the prior's strengths), exceeds this many
# nats: the prior log odds against a split, 0 (even odds) as derived. Confirmed, not
# re-chosen, on validation views (gains -8, 0, 1, 8 against fixed K): below 0 only the
# object gains, at several times its components; above 0 every scene loses. The figures
# are in docs/validation.md ("AUTO_REFINE_GAIN").
AUTO_REFINE_GAIN = 0.0
# "auto": the split score's shape term (vbgs.mapping.splits.surface_gain, derived there:
# how much better a child's own plane explains its cell's points along their normal than
# the component that explains them now). Off: on validation views it lost on the object and
# gained nothing elsewhere; the figures are in docs/validation.md ("AUTO_REFINE_SHAPE").
AUTO_REFINE_SHAPE = False
AUTO = "auto"


def components_arg(text: str) -> int | str:
    """A command line's components: digits become the integer K, anything else stays
    text for :func:`parse_components` to accept (``auto``, ``auto:MAX``) or refuse where
    the run's settings are checked (one message, whichever way the value came)."""
    return int(text) if text.strip().isdigit() else text.strip()


def parse_components(value) -> tuple[bool, int]:
    """``(auto, K)`` of a components setting: a positive integer K (the fixed capacity),
    ``"auto"`` (the count chosen from the data, at most :data:`AUTO_MAX_COMPONENTS`) or
    ``"auto:MAX"`` (at most MAX). A command line's text is read by
    :func:`components_arg` first."""
    if isinstance(value, str):
        text = value.strip().lower()
        if text == AUTO:
            return True, AUTO_MAX_COMPONENTS
        head, colon, tail = text.partition(":")
        if head == AUTO and colon:
            if tail.isdigit() and int(tail) >= 1:
                return True, int(tail)
            raise ValueError(f"components {value!r}: the most components auto may use must "
                             f"be a positive integer (auto:MAX, e.g. auto:50000), got "
                             f"{tail!r}")
    elif isinstance(value, int) and not isinstance(value, bool) and value >= 1:
        return False, value
    raise ValueError(f"components must be a positive integer (the capacity K), 'auto' (K "
                     f"chosen from the data, at most {AUTO_MAX_COMPONENTS}) or 'auto:MAX', "
                     f"got {value!r}")
