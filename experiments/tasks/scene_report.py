"""What a scene run says besides its record: warnings on stderr when part of the picture
is missing (points unlearned, components capped, test surface uncovered), and the PNG of
held-out views (``fit-scene --save``)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from vbgs.io_atomic import write_atomic

# A share of the training points left unlearned above this is said on stderr.
UNLEARNED_WARNING = 0.01


def warn_unlearned(share: float, task, search: str | None = None) -> None:
    """Say on stderr, in words, when a stream left part of its points unlearned (its
    budget of components spent before new ground arrived): the picture then misses it.
    ``search``: the candidate search the frames took (None: the task's)."""
    if share <= UNLEARNED_WARNING:
        return
    if (search or task.search) == "projective":  # its own cause comes first
        print(f"warning: {share:.1%} of the training points were not learned: the "
              f"projective search listed no component near them (a tile is a fixed number "
              f"of pixels, so frames spanning a wide range of depths lose points), so the "
              f"renders miss them; --search kdtree lists the nearest components wherever "
              f"they lie (the JSON's points_unlearned says how much)", file=sys.stderr)
        return
    print(f"warning: {share:.1%} of the training points were not learned: all "
          f"{task.components} components were spent before the stream reached that "
          f"ground, so the renders miss it; give more --components (the JSON's "
          f"points_unlearned says how much)", file=sys.stderr)


def warn_all(details: dict, task, uncovered: float,
             early: tuple[float, float] | None = None) -> None:
    """Every warning of a finished scene run (:func:`warn_unlearned`,
    :func:`warn_capped`, :func:`warn_budget_spent`, :func:`warn_forgotten`,
    :func:`warn_uncovered`); ``early``: the first views' PSNR when seen and at the end."""
    warn_unlearned(details.get("points_unlearned", 0.0), task, details.get("search_used"))
    warn_capped(details, task)
    warn_budget_spent(details, task, early)
    warn_forgotten(details, task)
    warn_uncovered(uncovered, details)


def warn_forgotten(details: dict, task) -> None:
    """Say on stderr when the map forgot components (:mod:`vbgs.mapping.change`): what the
    renders no longer show, and why it may be wrong on a world that did not change."""
    n = details.get("components_forgotten", 0)
    if not n:
        return
    from experiments.learners.vbgs_learner import task_config  # a VBGS task's alone

    config = task_config(task)
    colour = config.recolour_sigmas > 0  # colour counts too (by default with exact depth)
    gated = config.evidence.recolour_gate > 0  # a static world never opens the gate
    shown = (" or, once their depth had shown that the world changes, showed them in "
             "another colour" if gated else " or showed them in another colour")
    print(f"note: {n} components were forgotten: later frames saw through them"
          f"{shown if colour else ''} "
          f"{task.evidence.forget_after} frames in a row, so the map took what they showed "
          f"as gone and grew what stands there now; on a world that did not change this "
          f"removes thin structures the depth misses (posts, branches)"
          f"{' and, by colour, rims between differently coloured faces' if colour and not gated else ''}, "
          f"and --forget-after 0 keeps everything (the JSON's components_forgotten)",
          file=sys.stderr)


def warn_capped(details: dict, task) -> None:
    """Say on stderr when ``components = "auto"`` reached its most components: from then
    on it merged the cheapest neighbours to make room, as a fixed K does."""
    if details.get("components_capped"):
        print(f"warning: --components {task.components} reached its ceiling of "
              f"{details['components_capacity']} components; from then on the cheapest "
              f"neighbours were merged to make room for new ground, so the count is the "
              f"ceiling's, not the data's; give a higher ceiling (auto:MAX)", file=sys.stderr)


def warn_budget_spent(details: dict, task, early: tuple[float, float] | None) -> None:
    """Say on stderr when a fixed number of components was spent and neighbours were
    merged to make room for new ground (vbgs.inference.merge), and what that cost the
    views seen first: their PSNR when seen against at the end (``early``)."""
    rounds = details.get("merge_rounds", 0)
    if not rounds or isinstance(task.components, str):  # auto: warn_capped says it
        return
    cost, coarser = "", ""
    if early is not None and None not in early:
        when, end = early
        change = (f"lost {when - end:.2f} dB" if end < when else
                  f"gained {end - when:.2f} dB meanwhile")
        cost = (f"; the views seen first scored {when:.2f} dB when seen and {end:.2f} dB at "
                f"the end ({change}")
        cost += ", the JSON's early_psnr_when_seen and early_psnr_at_end)"
        levels = task.growth.spent_levels  # a number of levels, or "ground" (the default)
        if end < when and not (isinstance(levels, int) and levels > 0):
            coarser = (", or --spent-levels 1 grows all the ground met once they are all in "
                       "use on coarser cells, so fewer merges coarsen what was learned first")
    print(f"note: all {task.components} components were in use, so {rounds} rounds merged "
          f"{details.get('components_merged', 0)} neighbours the data tell apart least to "
          f"make room for new ground{cost}; more --components keeps more detail{coarser}",
          file=sys.stderr)


# A share of the test views' surface pixels drawn as background above this is said.
UNCOVERED_WARNING = 0.02
# ... and when the median component holds fewer points than this, the warning says the
# splats may be too small. The walk at 128 px / 60 frames: 50k components hold a median
# 5.8 points and leave 2.2 % of the test surface uncovered (21.46 dB), 20k hold 12.8 and
# leave 0.6 % (22.55 dB); at 50k a splat scale of 1.5 draws the walk's validation views
# at 22.70 dB against 21.35 at the default 1.2 (results/tuning/walk50k/splat_scale.md), and
# --splat-scale auto chooses it (vbgs.render.scale_fit).
FEW_POINTS = 10.0


def warn_uncovered(share: float, details: dict | None = None) -> None:
    """Say on stderr when the test views show background where their ground truth has a
    surface: ground the map missed, or that no training frame saw (JSON ``uncovered``).
    With a median of fewer than :data:`FEW_POINTS` points a component (the learner's
    ``details``: ``points_per_component``) and a fixed splat scale, also that the splats
    may be too small for the gaps, and what to try."""
    if share <= UNCOVERED_WARNING:
        return
    details = details or {}
    points = details.get("points_per_component")
    message = (f"warning: {share:.1%} of the test views' pixels with a surface are drawn as "
               f"background (no splat covers them): ground the map missed or no training "
               f"frame saw (the JSON's uncovered says how much)")
    if points is not None and 0 < points < FEW_POINTS and "splat_scale_chosen" not in details:
        message += (f"; or splats too small to meet: the median component learned "
                    f"{points:.1f} points, about a pixel's worth of surface, so fewer "
                    f"--components or --splat-scale auto (the scale that draws the arrived "
                    f"frames best) may draw it better")
    print(message, file=sys.stderr)


def save_views(path: str | Path, targets, renders, title: str, n: int = 4) -> None:
    """Ground truth (top) and render (bottom) of up to ``n`` held-out views in one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = min(n, len(targets))
    fig, axes = plt.subplots(2, n, figsize=(2.6 * n, 5.4), squeeze=False)
    for j in range(n):
        for i, (im, name) in enumerate(((targets[j], "ground truth"), (renders[j], "render"))):
            axes[i, j].imshow(np.clip(im, 0, 1))
            axes[i, j].set_title(f"{name}, view {j}", fontsize=9)
            axes[i, j].axis("off")
    fig.suptitle(title)
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, bbox_inches="tight"))
    plt.close(fig)
