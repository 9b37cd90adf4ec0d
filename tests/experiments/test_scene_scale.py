"""A scene in other units learns and renders the same: every length the renderer, growth
and tracking use is relative to the scene (a fixed near plane of 0.2 units once culled the
whole object given in kilometres: 9.48 against 19.48 dB)."""

import contextlib
import io
import json

import pytest

import vbgs.data.synthetic as synthetic
from experiments.run import main
from vbgs.data.scene import scale_scene


def psnr_at(monkeypatch, factor: float) -> float:
    make = synthetic.SCENES["object"]
    monkeypatch.setitem(synthetic.SCENES, "object",
                        lambda **kw: scale_scene(make(**kw), factor))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["fit-scene", "--scene", "object", "--size", "24", "--frames", "6",
                     "--test-views", "2", "--components", "100", "--json"])
    record = json.loads(out.getvalue().strip().splitlines()[-1])
    assert code == 0, record
    return record["psnr"]


def test_the_object_in_kilometres_metres_and_millimetres_scores_the_same(monkeypatch):
    scores = {f: psnr_at(monkeypatch, f) for f in (1e-3, 1.0, 1e3)}
    assert max(scores.values()) - min(scores.values()) < 0.1, scores
    assert scores[1.0] > 12.0, scores  # a fit, not the background


def test_a_scale_must_be_positive():
    scene = synthetic.make_scene("object", size=8, n_train=1, n_test=1)
    with pytest.raises(ValueError, match="finite number > 0"):
        scale_scene(scene, 0.0)
