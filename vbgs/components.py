"""The components setting: a fixed capacity K, or ``auto`` (the count chosen from the data).

Plain Python (no JAX, outside :mod:`vbgs.mapping`, whose package imports JAX): the
command line and the sweep's config check read it before
anything heavy is imported. What ``auto`` does is in :mod:`vbgs.mapping.mapper`
(``_auto_room``), :mod:`vbgs.inference.merge` (merges scored by the bound) and
:mod:`vbgs.inference.capacity` (slots grown in buckets).
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
AUTO_POINTS = 4.0
# "auto": frames between two rounds of merges scored by the bound (vbgs.inference.merge.
# bound_pairs); each round searches every component's neighbours (0.1-0.2 s at 20k).
AUTO_MERGE_EVERY = 4
# "auto": the split rule (vbgs.inference.grow.refinement_levels): a point seeds a finer
# component when its component explains its colour worse by more than this many nats.
AUTO_REFINE_GAIN = 2.0
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
