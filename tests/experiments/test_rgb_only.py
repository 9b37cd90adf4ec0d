"""RGB-only folders end to end: RGB and poses, no depth, a depth model (a tiny ONNX graph
built here that looks up the mono sensor model's depth of each frame)."""

import json

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")

from depth.stream import StreamConfig  # noqa: E402
from depth.testing import lookup_model  # noqa: E402
from experiments.studies.depth_study import mono_disparity  # noqa: E402
from experiments.tasks.depth_swap import EstimatedDepth  # noqa: E402
from experiments.run import main  # noqa: E402
from vbgs.data.blender import load_blender, write_blender  # noqa: E402
from vbgs.data.synthetic import make_scene  # noqa: E402

SIZE, FRAMES = 32, 8


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """The object at 32 px written in the Blender layout without its depth files, and
    ``m.onnx``: ``2 / d_mono + 0.3`` of each training frame, found by its RGB."""
    root = tmp_path_factory.mktemp("rgb_only")
    scene = make_scene("object", size=SIZE, n_train=FRAMES, n_test=2, seed=0, n_val=1)
    write_blender(scene, root)
    for path in root.rglob("*_depth.png"):
        path.unlink()
    rgb = np.stack([f.rgb for f in load_blender(root, require_depth=False).train])
    onnx.save(lookup_model(rgb, mono_disparity(scene.train, 0)), str(root / "m.onnx"))
    return root


def fit(folder, *extra):
    return ["fit-scene", "--scene", str(folder), "--size", str(SIZE), "--components", "600",
            "--frames", str(FRAMES), *extra]


def test_rgb_only_folder_without_a_model_is_refused_naming_the_way(folder, capsys):
    assert main(fit(folder)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no depth for" in err
    assert "--depth-model" in err and "python -m depth" in err


def test_rgb_only_folder_runs_end_to_end(folder, capsys):
    assert main(fit(folder, "--depth-model", str(folder / "m.onnx"), "--sensor", "mono",
                    "--json")) == 0
    out, err = capsys.readouterr()
    r = json.loads(out.strip().splitlines()[-1])
    assert r["depth_l1"] is None  # no test depth: RGB scores only, said once
    assert err.count("scored on RGB alone") == 1
    assert r["depth_source"] == "estimated" and r["depth_reference"] == "views"
    assert r["depth_aligned_on"] == [0, 1, 2, 3, 4, 5]  # the first six to arrive
    # measured: 47 % of the pixels cut (the background, about 40 % of the frames at
    # 32 px, and the depth edges); 16.48 dB (the background alone scores about 9 dB)
    assert r["depth_not_surface"] > 0.4
    assert r["psnr"] > 15.5 and 0 < r["components_used"] <= 600


def test_alignment_reads_arrived_frames_only(folder):
    """Frames are pulled one at a time; the first three (``views=3``) are released
    together once the third has arrived, every later one as it arrives; reversed, the
    alignment reads the last three frames of the folder."""
    scene = load_blender(folder, require_depth=False)
    order = list(range(FRAMES))[::-1]
    pulled = []

    def frames():
        for i in order:
            pulled.append(i)
            yield scene.train[i]

    stage = EstimatedDepth(str(folder / "m.onnx"), StreamConfig(kind="inverse", views=3),
                           positions=order)
    seen = [(frame, len(pulled)) for frame in stage(frames())]
    assert [n for _, n in seen] == [3, 3, 3, 4, 5, 6, 7, 8]
    assert all(np.array_equal(f.rgb, scene.train[i].rgb) for (f, _), i in zip(seen, order, strict=True))
    report = stage.report()
    assert report["depth_aligned_on"] == [7, 6, 5]
    assert all(f.depth.max() > 0 for f, _ in seen)


def test_init_reading_the_whole_stream_is_refused_with_a_model(folder, capsys):
    assert main(fit(folder, "--depth-model", str(folder / "m.onnx"), "--init", "data")) == 2
    assert "use init 'stream'" in capsys.readouterr().err
