"""End to end: ``fit-scene`` (sensor and estimated depth) and ``depth-study`` on tiny scenes."""

import json
import subprocess
import sys

import numpy as np
import pytest

from experiments.run import main
from vbgs.render.splats import load_ply

TINY = ["--scene", "object", "--components", "600", "--frames", "6", "--test-views", "2",
        "--size", "32"]


def test_fit_scene_json_ply_png(tmp_path):
    ply, png = tmp_path / "s.ply", tmp_path / "v.png"
    out = subprocess.run([sys.executable, "-m", "experiments.run", "fit-scene", *TINY,
                          "--ply", str(ply), "--save", str(png), "--json"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout.strip().splitlines()[-1])
    for key in ("psnr", "ssim", "depth_l1", "seconds_per_frame", "peak_memory_mb",
                "components_used", "early_psnr_when_seen", "early_psnr_at_end"):
        assert np.isfinite(r[key]), key
    # measured 19.86 dB, SSIM 0.728, depth L1 0.168, 372 splats drawn (seed 0); a render
    # of the background alone scores about 9 dB here
    assert r["psnr"] > 19.0 and r["ssim"] > 0.70 and r["depth_l1"] < 0.18
    assert 0 < r["components_used"] <= 600
    assert load_ply(ply).count == r["components_used"]
    assert png.stat().st_size > 5_000


def test_fit_scene_refuses_bad_input(capsys):
    assert main(["fit-scene", "--scene", "/no/such/folder"]) == 2
    assert "neither a dataset folder" in capsys.readouterr().err
    assert main(["fit-scene", *TINY[:2], "--components", "0"]) == 2
    assert "components must be a positive integer" in capsys.readouterr().err


def test_depth_study_recovers_alignment(tmp_path):
    # TINY's scene, size, components and frames: its sensor-depth run is the run of
    # test_fit_scene_json_ply_png above, whose executables the session's compile cache
    # holds (tests/conftest.py), so only the estimated-depth run compiles
    assert main(["depth-study", "--methods", "vbgs", "--components", "600", "--frames", "6",
                 "--size", "32", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "depth_study.md").read_text()
    assert "estimated" in text and "sensor" in text
    # the table says how it was made: the command and every setting
    assert (f"Command: `python -m experiments.run depth-study --scene object --components 600 "
            f"--frames 6 --size 32 --methods vbgs --steps-per-frame 50 --out {tmp_path}`"
            in text)
    assert "components = 600" in text and "disparity_scale = 2.0" in text
    import pandas as pd

    rows = pd.read_csv(tmp_path / "depth_study.csv").set_index("depth")
    assert (rows["components"] == 600).all() and (rows["frames"] == 6).all()
    assert "estimated = mono sensor model" in text
    est = rows.loc["estimated"]
    # p = 2 / d_mono + 0.3: the views' alignment is 1 / d = s p + t with s > 0; at 32 px
    # and 6 frames it is loose (the 128 px runs recover about 0.44, -0.10 for 0.5, -0.15)
    assert est["align_scale"] > 0
    # measured 15.51 dB estimated against 19.59 dB with sensor depth (align_scale 0.245)
    assert rows.loc["sensor", "psnr"] > 19.0 and est["psnr"] > 14.6
    assert est["psnr"] > rows.loc["sensor", "psnr"] - 5.0


def test_fit_scene_skips_points_already_learned(capsys):
    """``--budget-saturation``: points of cells learned that often are skipped and the
    JSON says their share."""
    assert main(["fit-scene", "--scene", "room", "--size", "48x32", "--components", "200",
                 "--frames", "4", "--test-views", "1", "--budget-saturation", "8",
                 "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["budget"]["saturation"] == 8
    # measured: 65% of the points skipped, 15.79 dB
    assert 0.4 < r["points_skipped"] < 0.9 and r["psnr"] > 15.0


def test_fit_scene_non_square_frames_with_a_budget(capsys):
    """``--size 48x32`` end to end, the frames thinned to a quarter (``--budget-points``)."""
    assert main(["fit-scene", "--scene", "room", "--size", "48x32", "--components", "200",
                 "--frames", "3", "--test-views", "1", "--budget-points", "400",
                 "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["size"] == [48, 32]
    assert r["budget"] == {"points": 400, "weighted": False, "saturation": 0}
    # measured 16.42 dB with 139 components drawn
    assert r["psnr"] > 15.6 and 0 < r["components_used"] <= 200
    with pytest.raises(SystemExit) as refused:  # argparse: exit status 2, the reason said
        main(["fit-scene", "--size", "640x", "--json"])
    assert refused.value.code == 2 and "WIDTHxHEIGHT" in capsys.readouterr().err


def test_fit_scene_hold_flags_reach_the_map(capsys):
    """``--hold-seeds --hold-paid`` set the map's ``growth.hold_seeds`` and
    ``growth.hold_paid``: the room at 32 px, whose 300 slots fill by its twelfth frame,
    then grows nothing it held before, so nothing is merged to pay for it (without the
    flags: 31 merged in 2 rounds, measured; the map's own test holds the pair)."""
    assert main(["fit-scene", "--scene", "room", "--size", "32", "--components", "300",
                 "--frames", "12", "--test-views", "1", "--hold-seeds", "--hold-paid",
                 "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["components_merged"] == 0 and r["merge_rounds"] == 0
    # measured 18.85 dB (18.59 without the flags)
    assert r["psnr"] > 18.0


def test_fit_scene_merge_ahead_reaches_the_map(capsys):
    """``--merge-ahead`` sets the map's ``growth.merge_ahead``: the room at 32 px, whose
    300 slots fill by its twelfth frame, pays for its new ground in one round that frees
    90 slots ahead (without it: 31 merged in 2 rounds, measured); a share the map refuses
    is refused in its words."""
    assert main(["fit-scene", "--scene", "room", "--size", "32", "--components", "300",
                 "--frames", "12", "--test-views", "1", "--merge-ahead", "0.3",
                 "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["merge_rounds"] == 1 and r["components_merged"] == 90
    assert r["psnr"] > 18.0  # measured 18.67 dB (18.59 without the flag)
    assert main(["fit-scene", "--scene", "room", "--size", "32", "--merge-ahead", "0.7",
                 "--json"]) != 0
    assert "growth.merge_ahead must be in [0, 0.5)" in capsys.readouterr().err


def test_fit_scene_spent_levels_reaches_the_map(capsys):
    """``--spent-levels`` sets the map's ``growth.spent_levels``: the room at 32 px, whose
    300 slots fill by its twelfth frame, grows the new ground of its last twelve frames on
    coarser cells and merges far less to pay for it (measured: 18 merged in 3 rounds,
    19.44 dB, against 113 in 12 rounds and 19.24 dB without the flag); a level count the
    map refuses is refused in its words."""
    assert main(["fit-scene", "--scene", "room", "--size", "32", "--components", "300",
                 "--frames", "24", "--test-views", "1", "--spent-levels", "1",
                 "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert r["merge_rounds"] <= 4 and r["components_merged"] < 40
    assert r["psnr"] > 19.0
    assert main(["fit-scene", "--scene", "room", "--size", "32", "--spent-levels", "-1",
                 "--json"]) != 0
    assert "growth.spent_levels must be a whole number" in capsys.readouterr().err


def test_fit_scene_through_background_forgets_what_left_against_the_background(capsys):
    """The map's ``evidence.through_background`` (on by default; ``--no-through-background``
    turns it off): under the Kinect, the changing object's pixels that now show the
    background see through the components of what left, so more are forgotten and the
    changed pixels are drawn better (32 px, 600 components, measured: 90 forgotten and
    14.55 dB on the changed pixels, against 28 and 14.10 with the flag off)."""
    scores = []
    for flag in ([], ["--no-through-background"]):
        assert main(["fit-scene", "--scene", "object-change", "--size", "32", "--components",
                     "600", "--test-views", "2", "--simulate-sensor", "kinect", "--sensor",
                     "kinect", *flag, "--json"]) == 0
        scores.append(json.loads(capsys.readouterr().out.strip().splitlines()[-1]))
    on, off = scores
    assert on["components_forgotten"] >= 60 and off["components_forgotten"] <= 40
    assert on["psnr_changed"] > 14.3 and on["psnr_changed"] > off["psnr_changed"] + 0.3
