"""``bench estep | raster | depth`` end to end, tiny: each writes its table and reports
rows whose figures are finite (``bench image`` and ``bench stream``: test_fit_image_cli,
test_bench_stream)."""

import functools
import json
import math

from experiments.benchmarks import bench
from experiments.run import main


def _bench(capsys, tmp_path, *args) -> dict:
    assert main(["bench", *args, "--out", str(tmp_path), "--json"]) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_bench_estep_compares_dense_and_sparse(tmp_path, capsys, monkeypatch):
    # 4 frames instead of the command's 60 (two full streams per component count), and
    # one timed frame instead of 6 (each frame's padded size compiles the timed update
    # anew, for each E-step)
    monkeypatch.setattr(bench, "bench_estep", functools.partial(bench.bench_estep, frames=4,
                                                                timing_frames=1))
    out = _bench(capsys, tmp_path, "estep", "--sizes", "16", "--components", "100")
    (row,) = out["rows"]
    assert (row["size"], row["components"]) == (16, 100) and row["points_per_frame"] > 0
    for estep in ("dense", "sparse"):
        assert row[f"{estep}_s_per_frame"] > 0 and row[f"{estep}_dropped"] == 0
        # measured 17.45 dB (4 frames of a 16 px object, data start)
        assert row[f"{estep}_psnr"] > 16.5
    assert abs(row["psnr_gap_db"]) < 1.0
    assert len((tmp_path / "bench_estep.csv").read_text().splitlines()) == 2


def test_bench_raster_times_forward_and_backward(tmp_path, capsys):
    out = _bench(capsys, tmp_path, "raster", "--sizes", "16", "--components", "100")
    (row,) = out["rows"]
    assert (row["impl"], row["size"], row["splats"], row["dropped"]) == ("xla", 16, 100, 0)
    assert 0 < row["forward_s"] and 0 < row["forward_backward_s"]
    assert (tmp_path / "bench_raster.csv").is_file()


def test_bench_depth_adapter_agrees_with_its_session(tmp_path, capsys):
    out = _bench(capsys, tmp_path, "depth", "--sizes", "32")
    (row,) = out["rows"]
    assert row["size"] == 32 and row["max_abs_diff"] < 1e-5
    assert math.isfinite(row["adapter_fps"]) and row["adapter_fps"] > 0
    assert (tmp_path / "bench_depth.md").is_file()
