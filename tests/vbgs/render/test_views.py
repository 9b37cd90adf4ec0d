"""vbgs.render.views: held-out views scored, and the share of their surface left uncovered."""

import numpy as np

from vbgs.data.formats import load_scene
from vbgs.render.camera import unproject
from vbgs.render.splats import Splats
from vbgs.render.views import evaluate


def test_uncovered_is_the_share_of_surface_pixels_no_splat_covers():
    scene = load_scene("object", size=32, n_train=2, n_test=1, seed=0)
    view = scene.test[0]
    xyz, rgb = unproject(view.camera, view.rgb, view.depth)
    side = float(np.median(np.asarray(view.depth)[view.depth > 0])) / view.camera.fx
    covs = np.broadcast_to((side**2) * np.eye(3, dtype=np.float32), (len(xyz), 3, 3))
    splats = Splats(xyz, covs.copy(), rgb, np.ones(len(xyz), np.float32))
    white = np.ones(3, np.float32)
    seen = evaluate(splats, [view], white)
    assert seen.uncovered < 0.03  # a splat on every pixel's own point
    half = splats._replace(opacities=np.where(xyz[:, 0] > np.median(xyz[:, 0]), 1.0, 0.0)
                           .astype(np.float32))
    assert 0.35 < evaluate(half, [view], white).uncovered < 0.65
    none = evaluate(splats._replace(opacities=np.zeros(len(xyz), np.float32)), [view], white)
    assert none.uncovered == 1.0
