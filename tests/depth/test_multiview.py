"""The views' own alignment of a relative depth model (depth.multiview)."""

import numpy as np
import pytest

from depth.multiview import View, align_views
from vbgs.data.synthetic import make_scene


def _views(size, n_train, count, disparity=True):
    """The object's first ``count`` views; the model's output ``2 / d + 0.3`` (inverse)
    or ``0.5 d + 1`` (relative), the empty background at the far end."""
    frames = make_scene("object", size=size, n_train=n_train, n_test=1, seed=0,
                        n_val=0).train[:count]
    out = []
    for f in frames:
        d = np.where(f.depth > 0, f.depth, 8.0)
        p = 2.0 / d + 0.3 if disparity else 0.5 * d + 1.0
        out.append(View(f.camera, f.rgb, p.astype(np.float32)))
    return out


@pytest.mark.slow
def test_views_recover_the_map_from_poses_and_colours():
    # 1 / d = 0.5 p - 0.15 exactly; measured 0.4892, -0.1412 (64 px, 6 of 60 views)
    a = align_views(_views(64, 60, 6), "inverse")
    assert a.space == "inverse"
    assert abs(a.scale - 0.5) < 0.03 and abs(a.shift + 0.15) < 0.03
    assert a.residual < 0.02


def test_one_view_or_one_centre_cannot_fix_a_scale():
    views = _views(16, 8, 2)
    with pytest.raises(ValueError, match="at least 2 views"):
        align_views(views[:1], "inverse")
    same_centre = [views[0], views[1]._replace(camera=views[0].camera)]
    with pytest.raises(ValueError, match="no baseline"):
        align_views(same_centre, "inverse")
    with pytest.raises(ValueError, match="needs no alignment"):
        align_views(views, "metric")


def test_the_map_runs_the_model_s_way():
    """Whatever it finds (16 px is too coarse to find much), depth falls as an inverse
    model's output rises (1/d = s p + t, s > 0) and rises with a relative model's
    (d = s p + t, s > 0): a view is never turned inside out."""
    for disparity, kind in ((True, "inverse"), (False, "relative")):
        a = align_views(_views(16, 8, 3, disparity), kind)
        assert a.space == ("inverse" if disparity else "depth") and a.scale > 0
