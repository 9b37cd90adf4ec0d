"""A dataset folder whose background has no depth (sky, a backdrop) works without flags:
its colour is learned from the pixels without depth and used to render and score."""

import json

import numpy as np

from experiments.run import main
from vbgs.data.blender import write_blender
from vbgs.data.scene import Frame
from vbgs.data.synthetic import make_scene

SKY = (0.35, 0.6, 0.9)


def with_sky(frame: Frame) -> Frame:
    """The frame with everything farther than 3.9 units replaced by sky without depth."""
    rgb, depth = frame.rgb.copy(), frame.depth.copy()
    far = ~(depth > 0) | (depth > 3.9)
    rgb[far], depth[far] = SKY, 0.0
    return frame._replace(rgb=rgb, depth=depth)


def test_rgb_folder_with_sky_needs_no_flags(tmp_path, capsys):
    scene = make_scene("object", size=32, n_train=6, n_test=2)
    folder = write_blender(scene._replace(train=[with_sky(f) for f in scene.train],
                                          test=[with_sky(f) for f in scene.test]),
                           tmp_path / "outdoor")
    args = ["fit-scene", "--scene", str(folder), "--components", "600", "--size", "32",
            "--json"]
    assert main(args) == 0
    auto = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    np.testing.assert_allclose(auto["background_rgb"], SKY, atol=1 / 255)  # 8-bit PNG colours
    assert main([*args, "--background", "0,0,0"]) == 0  # the wrong colour, fixed by hand
    black = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert black["background_rgb"] == [0.0, 0.0, 0.0]
    assert auto["psnr"] > black["psnr"] + 3.0, (auto["psnr"], black["psnr"])
    assert main([*args, "--background", "sky"]) == 2
    assert "R,G,B" in capsys.readouterr().err
