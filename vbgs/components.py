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
# samples, that fixes the cell side in place of a share of K: mapper._auto_room). Chosen
# on VALIDATION views, the best mean over object, room and walk, by `python -m
# experiments.run tune --scene object room walk --components auto --frames 60 --size 128
# --grid growth.auto_points=1,2,4 --out results/tuning/components` (mean.md): mean PSNR
# 21.89 / 21.83 / 20.15 dB at 4 / 2 / 1 (object 23.94 / 24.55 / 24.10 with 5153 / 9009 /
# 15300 components; room 22.71 / 23.07 / 23.05 with 22.9k / 41.8k / 70.5k; walk 19.03 /
# 17.87 / 13.29 with 13.4k / 36.9k / 131k: finer cells leave the walk's views holed).
# Under the Bayes-factor split rule (vbgs.mapping.splits, gain 0), 8 against 4 (`--grid
# growth.auto_points=8`, the same views): object 25.47 / 25.65 (18.1k / 18.0k), room
# 23.51 / 24.21 (49.4k / 61.4k), walk 22.28 / 22.33 (36.9k / 46.7k); 4 kept.
AUTO_POINTS = 4.0
# "auto": frames between two rounds of merges scored by the bound (vbgs.inference.merge.
# bound_pairs); 0: none (at auto:MAX the budget's merges still make room). Off since auto
# splits (below): on VALIDATION views, 128 px, 60 frames, split rule at 1 nat, merges
# every 4 frames against none (`python -m experiments.run tune --scene object room walk
# --components auto --grid growth.refine_gain=1 growth.merge=true,false`; merge=false
# also stops these rounds): object 24.97 / 25.83 dB (8.9k / 19.3k components), room
# 23.18 / 23.74 (29k / 56k), walk 21.06 / 22.92 (52k / 113k); every 12 frames at
# footprints 0.5: object 25.20 (26k), room 23.51 (75k), walk 22.08 (96k). The bound
# scores points, and the merges it allows cost pictures 0.6-1.9 dB; they held the count.
AUTO_MERGE_EVERY = 0
# "auto": the split rule (vbgs.mapping.splits, derived there): a child in a finer cell
# when its log Bayes factor, the colour evidence of every point its cell has shown less
# the Occam factors of all its parameters (from the prior's strengths), exceeds this many
# nats: the prior log odds against a split, 0 (even odds) as derived. Confirmed, not
# re-chosen, on VALIDATION views (128 px, 60 frames, 4 views; `python -m experiments.run
# tune --scene object room walk --components auto --grid growth.refine_gain=-8,8`, and
# `python -m experiments.studies.val_probe fit-scene --scene S --components auto` at 0 and 1;
# val_psnr, components):
#   gain -8: object 26.78 (73.1k), room 24.10 (131k: the ceiling), walk 22.35 (131k)
#   gain  0: object 25.65 (18.0k), room 24.21 (61.4k), walk 22.33 (46.7k)
#   gain  1: object 25.55 (17.2k), room 24.22 (59.1k), walk 22.31 (44.4k)
#   gain  8: object 25.00 (14.0k), room 23.90 (50.0k), walk 21.97 (36.7k)
#   fixed K 20000 / 50000 (the same views): object 26.58 / 27.35, room 22.67 / 24.03,
#   walk 21.59 / 21.07
# Below 0 only the object's picture rises, at 4 times its components, while room and walk
# go to the ceiling for nothing; above 0 every scene loses 0.3-0.65 dB. Without the
# spatial Occam factors (the colour mean's alone, gain 1): object 26.53 (32.8k), room
# 24.70 (104k), walk 22.91 (99k). The rule it replaced (one frame's colour gain at noise
# sigma_c > 1 nat): object 26.38 (42.3k), room 24.09 (119k), walk 22.83 (131k); at 16
# nats 23.99 (14.8k), 23.75 (52.9k), 22.00 (41.6k). What the object still misses against
# fixed K is not the count: under this rule (gain 1) a finer first frame (auto_points 1 /
# 2: 25.36 dB with 29.3k / 25.23 with 20.8k) or children at the level-0 prior scale
# (24.75, 17.5k) do worse; fixed K refines everywhere at random, and the rule counts
# colour, not the geometry of curved surfaces and silhouettes.
AUTO_REFINE_GAIN = 0.0
# "auto": the split score's shape term (vbgs.mapping.splits.surface_gain, derived there:
# how much better a child's own plane explains its cell's points along their normal than
# the component that explains them now). Off: on VALIDATION views (128 px, 60 frames, the
# first 4; experiments.tasks.scene_task.run_scene on experiments.studies.val_probe's views with the
# growth fields set; val_psnr, components, births + splits):
#   on,  gain 0: object 25.16 (17.8k: 7.8k + 9.9k) against 25.65 (18.0k) off
#   on,  auto_points 8, gain 8: object 24.61 (12.5k), room 23.12 (40.9k: 18.9k + 22.0k),
#        walk 22.07 (23.6k: 11.6k + 12.0k) against walk 22.16 (25.0k: 11.8k + 13.1k) off
# A form that credited the child its prior's spread along the normal (looser than a
# parent fitted to many points: a gain on flat ground too) gave object 26.21 (29.9k) but
# walk 22.18 (70.5k: 26.0k + 44.4k splits against 19.1k): no better than a lower gain.
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
