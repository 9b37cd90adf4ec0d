"""Scores of a run on a scene that changed while it was streamed (:mod:`vbgs.data.changing`).

A map's final render of each test view is scored four ways: against the world as it is
now (the run's ``psnr``, as for any scene), against the world as it was before the
changes (``psnr_first_state``: what the map still draws of what is gone), and, against
the world as it is now, over the pixels whose true colour or depth differs between the
two states (``psnr_changed``: has it learned the change?) and over those that do not
(``psnr_unchanged``: has it kept what is still there?). The pixel PSNRs pool every test
view's pixels of their kind (one mean squared error over all of them).

A stream also renders the test views once more, as the map stood just before the first
frame of the changed world arrived (:func:`frames_before_change`): over the unchanged
pixels that is ``psnr_unchanged_before`` (what it had learned of the first state that
the change leaves standing), and ``unchanged_retention`` is ``psnr_unchanged`` minus it
(the first state's retention on the unchanged pixels: < 0, learning the changed world
lost some of what did not change; > 0, the later frames added to it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from vbgs.data.changing import changed_pixels
from vbgs.data.scene import Scene
from vbgs.render.metrics import psnr, psnr_of_mse

FIELDS = ("change_frames", "psnr_first_state", "psnr_changed", "psnr_unchanged",
          "changed_share", "psnr_unchanged_before", "unchanged_retention")


def frames_before_change(changes: Sequence[int], order) -> int | None:
    """How many frames of the stream ``order`` (training frame indices) arrive before the
    first frame that shows a changed world (index >= the first of ``changes``); None
    when the world does not change or the stream starts in the changed world."""
    if not changes:
        return None
    first = min(changes)
    later = [p for p, i in enumerate(np.asarray(order).tolist()) if i >= first]
    return later[0] if later and later[0] > 0 else None


def change_scores(scene: Scene, renders: list[np.ndarray],
                  before: list[np.ndarray] | None = None) -> dict:
    """The scores of the module docstring from the final ``renders`` of ``scene.test``
    (``[h, w, 3]`` each) and, where given, the renders ``before`` the first change; None
    for each field when the scene does not change (the last two without ``before``)."""
    if not scene.first_state:
        return dict.fromkeys(FIELDS)
    masks = [changed_pixels(a, b) for a, b in zip(scene.first_state, scene.test, strict=True)]
    changed, kept = _split(renders, scene, masks)
    first = [psnr(r, f.rgb) for r, f in zip(renders, scene.first_state, strict=True)]
    kept_now = _pooled(kept)
    kept_before = _pooled(_split(before, scene, masks)[1]) if before is not None else None
    retention = (kept_now - kept_before if kept_now is not None and kept_before is not None
                 else None)
    return {"change_frames": list(scene.changes),
            "psnr_first_state": float(np.mean(first)),
            "psnr_changed": _pooled(changed), "psnr_unchanged": kept_now,
            "changed_share": float(len(changed) / (len(changed) + len(kept))),
            "psnr_unchanged_before": kept_before, "unchanged_retention": retention}


def _split(renders, scene: Scene, masks) -> tuple[np.ndarray, np.ndarray]:
    """Squared errors of ``renders`` against ``scene.test`` (mean over RGB), pooled over
    the changed pixels and over the others."""
    errors = [((np.asarray(r, np.float64) - np.asarray(f.rgb, np.float64)) ** 2).mean(-1)
              for r, f in zip(renders, scene.test, strict=True)]
    changed = np.concatenate([e[m] for e, m in zip(errors, masks, strict=True)])
    kept = np.concatenate([e[~m] for e, m in zip(errors, masks, strict=True)])
    return changed, kept


def _pooled(squared: np.ndarray) -> float | None:
    """PSNR of pooled per-pixel squared errors (None: no such pixel)."""
    return None if squared.size == 0 else psnr_of_mse(float(squared.mean()))
