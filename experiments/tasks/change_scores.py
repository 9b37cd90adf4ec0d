"""Scores of a run on a scene that changed while it was streamed (:mod:`vbgs.data.changing`).

A map's final render of each test view is scored four ways: against the world as it is
now (the run's ``psnr``, as for any scene), against the world as it was before the
changes (``psnr_first_state``: what the map still draws of what is gone), and, against
the world as it is now, over the pixels whose true colour or depth differs between the
two states (``psnr_changed``: has it learned the change?) and over those that do not
(``psnr_unchanged``: has it kept what is still there?). The pixel PSNRs pool every test
view's pixels of their kind (one mean squared error over all of them).
"""

from __future__ import annotations

import numpy as np

from vbgs.data.changing import changed_pixels
from vbgs.data.scene import Scene
from vbgs.render.metrics import psnr, psnr_of_mse

FIELDS = ("change_frames", "psnr_first_state", "psnr_changed", "psnr_unchanged",
          "changed_share")


def change_scores(scene: Scene, renders: list[np.ndarray]) -> dict:
    """The scores of the module docstring from the final ``renders`` of ``scene.test``
    (``[h, w, 3]`` each); None for each field when the scene does not change."""
    if not scene.first_state:
        return dict.fromkeys(FIELDS)
    masks = [changed_pixels(a, b) for a, b in zip(scene.first_state, scene.test, strict=True)]
    errors = [((np.asarray(r, np.float64) - np.asarray(f.rgb, np.float64)) ** 2).mean(-1)
              for r, f in zip(renders, scene.test, strict=True)]
    changed = np.concatenate([e[m] for e, m in zip(errors, masks, strict=True)])
    kept = np.concatenate([e[~m] for e, m in zip(errors, masks, strict=True)])
    first = [psnr(r, f.rgb) for r, f in zip(renders, scene.first_state, strict=True)]
    return {"change_frames": list(scene.changes),
            "psnr_first_state": float(np.mean(first)),
            "psnr_changed": _pooled(changed), "psnr_unchanged": _pooled(kept),
            "changed_share": float(len(changed) / (len(changed) + len(kept)))}


def _pooled(squared: np.ndarray) -> float | None:
    """PSNR of pooled per-pixel squared errors (None: no such pixel)."""
    return None if squared.size == 0 else psnr_of_mse(float(squared.mean()))
