"""The real motorcycle RGB-D frame is reachable from commands; depth-study names its
optional onnx dependency when it is missing."""

import json
import sys

import numpy as np

from experiments.studies.oracle import masked_psnr, oracle_splats, render_oracle
from experiments.run import main
from vbgs.data.formats import load_scene
from vbgs.render.camera import valid_depth

SIZE = 48


def test_motorcycle_loads_by_name_as_a_one_view_scene():
    scene = load_scene("motorcycle", size=SIZE)
    assert scene.name == "motorcycle" and len(scene.train) == 1 and not scene.test
    frame = scene.train[0]
    assert frame.rgb.shape == (32, SIZE, 3) and frame.camera.width == SIZE
    assert 0.9 < valid_depth(frame.depth).mean() < 0.96  # 93% of pixels have depth
    lo, hi = scene.bounds
    assert 2.0 < lo[2] and hi[2] < 5.1  # metres, as stereo.py documents


def test_oracle_command_on_the_real_frame(capsys):
    assert main(["oracle", "--scene", "motorcycle", "--size", str(SIZE), "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["neighbour"] == -1 and out["psnr_neighbour"] is None  # no neighbour: null
    assert "NaN" in out["psnr_neighbour_note"]
    # pixels without depth get no splat and show the background: about 21 dB over the
    # whole view at this size, far more where depth is valid (checked below)
    assert 19.0 < out["psnr_same"] < 30.0 and out["depth_l1_same"] < 0.05
    scene = load_scene("motorcycle", size=SIZE)
    frame = scene.train[0]
    rgb, _ = render_oracle(oracle_splats(frame), frame, scene.background)
    assert masked_psnr(np.asarray(rgb), frame.rgb, valid_depth(frame.depth)) > 35.0


def test_fit_scene_refuses_a_scene_without_test_views(capsys):
    assert main(["fit-scene", "--scene", "motorcycle", "--size", "32", "--frames", "1",
                 "--components", "50"]) == 2
    err = capsys.readouterr().err
    assert "has no held-out test views" in err and "Traceback" not in err


def test_depth_study_without_onnx_names_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "onnx", None)  # import onnx now raises ImportError
    assert main(["depth-study", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "pip install -e '.[depth-study]'" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()  # refused before any work
