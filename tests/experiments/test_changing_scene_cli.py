"""``fit-scene --scene object-change``: the changing world's scores in the record."""

import json

import pytest

from experiments.run import main
from experiments.tasks.change_scores import frames_before_change

TINY = ["fit-scene", "--components", "600", "--frames", "8", "--test-views", "2",
        "--size", "32", "--json"]


def test_a_changing_scene_reports_what_changed_and_what_was_kept(capsys):
    assert main([*TINY, "--scene", "object-change"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["change_frames"] == [4]
    assert 0.05 < r["changed_share"] < 0.5
    # a map that never forgets: the pixels that changed are drawn far worse than the rest
    # (measured 12.7 against 20.3 dB at 12 frames)
    assert r["psnr_unchanged"] > r["psnr_changed"] + 3
    assert r["psnr_first_state"] > 10
    # the unchanged pixels as the map drew them just before the changed world arrived,
    # and what the end kept of them
    assert r["psnr_unchanged_before"] > 10
    assert r["unchanged_retention"] == pytest.approx(
        r["psnr_unchanged"] - r["psnr_unchanged_before"])


def test_a_static_scene_has_no_change_scores(capsys):
    assert main([*TINY, "--scene", "object", "--frames", "4"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["change_frames"] is None and r["psnr_changed"] is None
    assert r["unchanged_retention"] is None


def test_the_frames_before_a_change_follow_the_stream_order():
    assert frames_before_change([15], range(30)) == 15
    assert frames_before_change([4], [0, 5, 1, 2]) == 1  # frame 5 shows the changed world
    assert frames_before_change([4], [5, 0, 1]) is None  # it starts in the changed world
    assert frames_before_change([], range(8)) is None  # a world that does not change
