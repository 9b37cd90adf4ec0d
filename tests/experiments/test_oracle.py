"""The oracle check: splats built from ground truth, rendered back by the real renderer."""

import json

import pytest

from experiments.studies.oracle import oracle_score
from experiments.run import main
from vbgs.data import synthetic
from vbgs.data.blender import write_blender
from vbgs.data.scene import Scene

# Trajectory positions (of 60) used as the training frames: a source view, its
# neighbour, and three frames around the trajectory (the "surroundings").
POSITIONS = (0, 1, 15, 30, 45)
# Measured at 64 px (same / neighbour-covisible / surround): room 35.0 / 19.3 / 26.8 dB,
# object 37.5 / 13.6 / 21.8 dB. Floors sit a little below. A renderer without the
# clamped Jacobian and frustum culling (and the old 0.01 near plane) gives 10.8 dB
# surround on the room.
FLOORS = {"room": (30.0, 18.0, 25.0), "object": (30.0, 12.5, 20.0)}


def small_scene(name: str, size: int = 64) -> Scene:
    train_poses, test_poses = getattr(synthetic, f"{name}_poses")(60, 1, 0)
    frames = synthetic.render_views(name, [train_poses[i] for i in POSITIONS], size)
    full = synthetic.make_scene(name, size=8, n_train=1, n_test=1)  # bounds and background
    return Scene(name, frames, frames[:1], full.bounds, full.background)


@pytest.mark.parametrize("name", ["room", "object"])
def test_oracle_reproduces_the_view_and_its_neighbours(name):
    scene = small_scene(name)
    same, neighbour, surround = FLOORS[name]
    score = oracle_score(scene)
    assert score.psnr_same >= same and score.depth_l1_same < 0.02, score
    assert score.psnr_neighbour >= neighbour and score.covisible > 0.25, score
    assert score.psnr_surround >= surround, score
    # The clamp and the frustum guard band, not the near plane, keep the splats beside
    # and behind the camera out of the picture: the same holds with a near plane at 0.01.
    close = oracle_score(scene, near=0.01)
    assert close.psnr_surround >= surround, close


def test_oracle_command_on_a_loaded_folder(tmp_path, capsys):
    scene = small_scene("room", size=48)  # its test view, a training frame's twin, replaced
    test = synthetic.render_views("room", [synthetic.room_poses(60, 1, 0)[0][7]], 48)
    write_blender(scene._replace(test=test), tmp_path / "walk")
    assert main(["oracle", "--scene", str(tmp_path / "walk"), "--size", "48", "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["psnr_same"] >= 30.0 and result["psnr_surround"] >= 24.0, result
    assert main(["oracle", "--scene", str(tmp_path / "walk"), "--view", "9"]) == 2
    assert "not a training frame" in capsys.readouterr().err
