"""``python -m experiments.run colour-gap`` end to end, tiny: the streamed (lumped) colour
fit against exact least squares and the posterior colours, each scored on held-out views
(its refusals: test_cli_bad_input)."""

import json

import pytest

from experiments.run import main


def test_colour_gap_command_scores_each_colouring(capsys):
    # render-bound's and tune's tiny shapes (150 components, 3 frames, 16 px): the
    # learner is compiled once for the three commands
    assert main(["colour-gap", "--components", "150", "--frames", "3", "--size", "16",
                 "--test-views", "1", "--iterations", "10", "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (out["components"], out["frames"], out["size"]) == (150, 3, 16)
    assert 0 < out["cg_iterations"] <= 10 and out["exact_seconds"] > 0
    # measured 18.24 (posterior), 18.28 (lumped, streamed), 18.28 (lumped, final),
    # 18.29 dB (exact); a render of the background alone scores about 9 dB here
    for name, measured in (("posterior", 18.24), ("lumped_stream", 18.28),
                           ("lumped_final", 18.28), ("exact", 18.29)):
        assert out[f"{name}_psnr"] == pytest.approx(measured, abs=0.5), name
        assert 0.6 < out[f"{name}_ssim"] <= 1.0, name
    assert out["gap_db"] == pytest.approx(out["exact_psnr"] - out["lumped_stream_psnr"])
    assert abs(out["gap_db"]) < 0.3  # the lumped fit is close to exact here
