"""``python -m experiments.run``: bad input is refused before any work, one line, exit 2;
Ctrl-C ends with one line and exit 130."""

import json

import pytest

import experiments.tasks.image_task as image_task
import experiments.tasks.scene_task as scene_task
from experiments.run import main

SCENE = ["fit-scene", "--scene", "object", "--components", "600", "--frames", "6",
         "--test-views", "2", "--size", "32"]
IMAGE = ["fit-image", "--image", "coffee", "--size", "16", "--components", "50"]


@pytest.fixture
def no_fit(monkeypatch):
    """Fail the test if a fit starts: every refusal below must come before the work."""
    def fit(*a, **k):
        raise AssertionError("the fit started before the input was checked")

    monkeypatch.setattr(image_task, "run_image", fit)
    monkeypatch.setattr(scene_task, "run_scene", fit)


def _refused(argv, capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "Traceback" not in err
    return err


# case 7 ------------------------------------------------------------------------------


def test_save_to_a_folder_is_refused_and_writes_nothing(tmp_path, capsys, no_fit):
    folder = tmp_path / "views"
    folder.mkdir()
    err = _refused([*IMAGE, "--save", str(folder)], capsys)
    assert f"--save {folder} is a folder; give a file name ending in .png" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["views"]  # no views.png beside it


def test_output_names_need_their_suffix(tmp_path, capsys, no_fit):
    err = _refused([*IMAGE, "--save", str(tmp_path / "fit")], capsys)
    assert "the file name must end in .png" in err
    err = _refused([*SCENE, "--ply", str(tmp_path / "splats.png")], capsys)
    assert "the file name must end in .ply" in err


def test_ply_into_a_folder_or_under_a_file_is_refused_before_the_fit(tmp_path, capsys, no_fit):
    err = _refused([*SCENE, "--ply", str(tmp_path)], capsys)
    assert f"--ply {tmp_path} is a folder" in err
    blocker = tmp_path / "notes.txt"
    blocker.write_text("x")
    err = _refused([*SCENE, "--save", str(blocker / "views.png")], capsys)
    assert f"{blocker} is a file, not a folder" in err


# case 9 ------------------------------------------------------------------------------


@pytest.mark.parametrize("argv, message", [
    (["fit-image", "--size", "1"],
     "--components 2000 is not fewer than the 1 pixels to fit (1x1 image)"),
    (["fit-image", "--size", "8", "--components", "64"],
     "--components 64 is not fewer than the 64 pixels to fit (8x8 image)"),
    (["fit-scene", "--size", "1", "--frames", "3", "--components", "3"],
     "--components 3 is not fewer than the 3 pixels to fit (at most 3 frames x 1x1)"),
])
def test_more_components_than_pixels_is_refused(argv, message, capsys, no_fit):
    err = _refused(argv, capsys)
    assert message in err and "the score would mean nothing" in err


def test_a_score_with_no_component_used_is_flagged(monkeypatch, capsys):
    monkeypatch.setattr(image_task, "run_image", lambda task, progress, image: {
        "psnr": 130.0, "ssim": 1.0, "components_used": 0, "images": {}})
    assert main([*IMAGE, "--json"]) == 0
    captured = capsys.readouterr()
    result = json.loads(captured.out.splitlines()[-1])
    assert result["warning"].startswith("warning: components_used is 0")
    assert captured.err.startswith("warning: components_used is 0 (no component explains")


# case 10 -----------------------------------------------------------------------------


def test_zero_test_views_is_named(capsys, no_fit):
    err = _refused([*SCENE, "--test-views", "0"], capsys)
    assert "--test-views must be at least 1 (the scores are measured on held-out views), got 0" \
        in err


# case 5 ------------------------------------------------------------------------------


def test_ctrl_c_is_one_line_and_status_130(monkeypatch, capsys):
    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(image_task, "run_image", interrupted)
    assert main(IMAGE) == 130
    assert capsys.readouterr().err == "interrupted\n"


@pytest.mark.parametrize("extra, message", [
    (["--iterations", "0"], "--iterations must be at least 1"),
    (["--ridge", "0"], "colour_ridge must be > 0"),
])
def test_colour_gap_refuses_bad_input_before_any_work(extra, message, capsys, monkeypatch):
    import experiments.studies.colour_gap as colour_gap

    def gap(*a, **k):
        raise AssertionError("the diagnostic started before the input was checked")

    monkeypatch.setattr(colour_gap, "colour_gap", gap)
    err = _refused(["colour-gap", "--components", "100", "--frames", "2", "--size", "16",
                    *extra], capsys)
    assert message in err


def test_a_failing_json_run_prints_one_json_object_with_the_error(capsys):
    """--json: a caller parsing stdout's last line gets the failure as an object."""
    import json

    from experiments.run import main

    assert main(["fit-scene", "--scene", "/no/such/folder", "--json"]) == 2
    out, err = capsys.readouterr()
    record = json.loads(out.strip().splitlines()[-1])
    assert "/no/such/folder" in record["error"] and record["error"] in err
    assert main(["fit-scene", "--scene", "/no/such/folder"]) == 2
    assert capsys.readouterr().out == ""  # without --json, stdout stays empty
