"""``fit-scene --scene object-change``: the changing world's scores in the record."""

import json

from experiments.run import main

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


def test_a_static_scene_has_no_change_scores(capsys):
    assert main([*TINY, "--scene", "object", "--frames", "4"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["change_frames"] is None and r["psnr_changed"] is None
