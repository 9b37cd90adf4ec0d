"""End to end: ``fit-scene --poses track|odometry`` on a tiny scene, and its refusals."""

import json

import numpy as np
import pytest

from experiments.run import main

# the shapes of the other tiny fit-scene tests (test_fit_scene_cli, test_walk_scene): this
# run reuses their compiled learner (with 500 components: 20.1 CPU s cold, 13.8 after
# test_fit_scene_cli)
TINY = ["--scene", "room", "--components", "600", "--frames", "6", "--test-views", "2",
        "--size", "32"]


def test_fit_scene_tracks(tmp_path, capsys):
    # in-process: a process start and JAX import fewer (test_fit_scene_cli runs fit-scene
    # as a real process)
    png = tmp_path / "t.png"
    assert main(["fit-scene", *TINY, "--poses", "odometry", "--drift", "0.01,0.5", "--plot",
                 str(png), "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    for key in ("ate_rmse", "rpe_trans", "rpe_rot_deg", "odometry_ate_rmse",
                "tracking_seconds_per_frame", "psnr"):
        assert np.isfinite(r[key]), key
    assert r["poses"] == "odometry" and len(r["pose_errors"]) == 6
    assert len(r["pose_sigmas"]) == 5  # the first pose is given
    # (6 frames around the room are 60 degrees apart, too little overlap at 32 px for a
    # meaningful figure: tests/vbgs/tracking/test_register.py checks the accuracy)
    assert png.stat().st_size > 5_000


def test_fit_scene_says_which_directions_the_depth_leaves_free(capsys):
    # a tiny walk under a Kinect: depth on the near road only, a plane that leaves the
    # motion along it free (said on stderr, listed in the JSON). Its 6 frames are 5.5
    # units apart (the full walk's 0.55 at 60): the track is lost after the second
    # (measured ATE 8.2 units; the full walk at 128 px: 5.9 mm), and the pose_sigmas say
    # so (0.2-0.8 units, 3.3 degrees) where the map registration alone said 0.4 mm
    walk = ["--scene", "walk", "--components", "600", "--frames", "6", "--test-views", "2",
            "--size", "32", "--simulate-sensor", "kinect", "--sensor", "kinect"]
    assert main(["fit-scene", *walk, "--poses", "track", "--json"]) == 0
    out = capsys.readouterr()
    r = json.loads(out.out.strip().splitlines()[-1])
    assert r["tracking_degenerate_frames"] == [2, 3, 4, 5, 6]
    assert len(r["tracking_degenerate_directions"]) == 5
    line = next(t for t in out.err.splitlines() if t.startswith("warning: tracking, frames 2 "))
    assert "translation along" in line  # with the averaged depth: rotations about y and z
    #                                     and translation along z (before: translations)
    assert "not constrained by the depth (planar geometry)" in out.err
    assert "direct RGB-D alignment" in out.err
    sigmas = np.asarray(r["pose_sigmas"], float)
    assert sigmas.shape == (5, 2) and np.all(np.isfinite(sigmas))
    assert np.all(sigmas[:, 0] > 0.1)  # honest: the track is lost


def test_fit_scene_refuses_what_tracking_cannot_run(capsys):
    cases = [(["--poses", "track", "--method", "gradient"], "use --method vbgs"),
             (["--poses", "track", "--order", "shuffled"], "temporal order"),
             (["--poses", "odometry", "--init", "data"], "--init stream"),
             (["--poses", "odometry", "--drift", "0.01"], "SIGMA_T,SIGMA_R"),
             (["--plot", "x.png"], "--plot draws the tracked trajectory")]
    for extra, message in cases:
        assert main(["fit-scene", *TINY, *extra]) == 2, extra
        assert message in capsys.readouterr().err, extra


@pytest.mark.slow  # the refinement is off by default (experiments.tasks.tracking.PHOTOMETRIC)
def test_fit_scene_tracks_photometrically(monkeypatch, capsys):
    # the photometric refinement is off by default (experiments.tasks.tracking.PHOTOMETRIC);
    # on, a tiny walk under a Kinect (depth on the near road only: every frame refined,
    # the second from the search) runs end to end
    import experiments.tasks.tracking as tracking

    monkeypatch.setattr(tracking, "PHOTOMETRIC", True)
    calls = []
    monkeypatch.setattr(tracking.TrackedLearner, "search",
                        lambda self, *a, _s=tracking.TrackedLearner.search: calls.append(1)
                        or _s(self, *a))
    walk = ["--scene", "walk", "--components", "600", "--frames", "6", "--test-views", "2",
            "--size", "32", "--simulate-sensor", "kinect", "--sensor", "kinect"]
    assert main(["fit-scene", *walk, "--poses", "track", "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert np.isfinite(r["ate_rmse"]) and np.isfinite(r["psnr"]) and calls == [1]
    assert len(r["pose_sigmas"]) == 5 and np.all(np.isfinite(r["pose_sigmas"]))
