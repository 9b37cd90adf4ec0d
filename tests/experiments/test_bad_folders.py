"""Data as users bring it: a small Blender folder broken the ways users break them. Each
is refused before any work, exit 2, one line naming the key or the frame, no traceback;
with --json one object with an error field (issue "Data as users bring it")."""

import json

import numpy as np
import pytest

from experiments.run import main
from vbgs.data.blender import write_blender
from vbgs.data.synthetic import object_scene


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    # 32 px and (below) 600 components: the shapes of the other tiny object runs
    # (test_fit_scene_cli, test_background_cli), whose compiled learner the clean run reuses
    return write_blender(object_scene(size=32, n_train=4, n_test=2, seed=0),
                         tmp_path_factory.mktemp("clean") / "scene")


def broken(folder, tmp_path, change):
    """A copy of the folder whose transforms_train.json ``change(meta)`` edits."""
    import shutil

    out = tmp_path / "broken"
    shutil.copytree(folder, out)
    path = out / "transforms_train.json"
    meta = json.loads(path.read_text())
    change(meta)
    path.write_text(json.dumps(meta))
    return out


def set_all(key, value):
    def change(meta):
        meta[key] = value
        for f in meta["frames"]:
            f.pop(key, None)
    return change


def drop_fl_and(key_value):
    def change(meta):
        for k in ("fl_x", "fl_y", "camera_angle_x"):
            meta.pop(k, None)
        meta.update(key_value)
    return change


def pose(edit):
    def change(meta):
        m = np.asarray(meta["frames"][1]["transform_matrix"], float)
        meta["frames"][1]["transform_matrix"] = edit(m).tolist()
    return change


def scaled(m):
    m[:3, :3] *= 2
    return m


def sheared(m):
    m[:3, :3] = m[:3, :3] @ np.array([[1, 0.4, 0], [0, 1, 0], [0, 0, 1.0]])
    return m


def reflected(m):
    m[:3, 0] *= -1
    return m


CASES = [
    ("fl_x zero, no angle", drop_fl_and({"fl_x": 0}), "positive 'fl_x'"),
    ("fl_x as text", set_all("fl_x", "41.7"), "'fl_x' is '41.7', not a number"),
    ("angle in degrees", drop_fl_and({"camera_angle_x": 39.6}), "in degrees? 39.6 degrees"),
    ("angle zero", drop_fl_and({"camera_angle_x": 0}), "'camera_angle_x' is 0"),
    ("rotation scaled", pose(scaled), "lengths [2.0, 2.0, 2.0] (scaled)"),
    ("rotation sheared", pose(sheared), "not perpendicular (sheared)"),
    ("a reflection", pose(reflected), "determinant -1 (a reflection)"),
]


@pytest.mark.parametrize("name, change, message", CASES, ids=[c[0] for c in CASES])
def test_a_broken_folder_is_refused_in_one_line(folder, tmp_path, capsys, name, change,
                                                message):
    bad = broken(folder, tmp_path, change)
    code = main(["fit-scene", "--scene", str(bad), "--components", "50", "--size", "32",
                 "--json"])
    out, err = capsys.readouterr()
    assert code == 2, (name, err)
    assert message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert message in json.loads(out.strip().splitlines()[-1])["error"]


@pytest.fixture(scope="module")
def clean_run(folder):
    """fit-scene on the clean folder, once for the tests below: exit code and JSON record."""
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["fit-scene", "--scene", str(folder), "--components", "600", "--size",
                     "32", "--frames", "60", "--json"])
    return code, json.loads(out.getvalue().strip().splitlines()[-1])


def test_the_clean_folder_runs(clean_run):
    code, r = clean_run
    assert code == 0 and np.isfinite(r["psnr"])


def test_the_record_says_what_ran_not_what_was_asked(clean_run):
    """The folder holds 4 training, 2 test and 4 validation views: asked for 60 and 8
    (and 4), the JSON reports 4 and 2 (and 4), and what was asked beside those that
    differ."""
    _, r = clean_run
    assert (r["frames"], r["n_test"], r["n_val"]) == (4, 2, 4)
    assert (r["frames_asked"], r["n_test_asked"]) == (60, 8) and "n_val_asked" not in r
