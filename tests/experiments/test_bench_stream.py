"""bench stream: one row streams every frame once and accounts for each of them."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from experiments.benchmarks.bench_stream import (
    LARGE_BUDGET,
    _prior,
    device_rows,
    large_cells,
    speedups,
    stream_row,
)
from vbgs.data.synthetic import object_scene


def test_bench_stream_command_counts_every_frame_and_pads_above_the_points(tmp_path, capsys):
    """``bench stream`` end to end, tiny: each row streams every frame once (the sparse
    row all 4, the dense row its at most 8), pads above the points, and the tables and
    the one-frame profile are written; ``--devices 2``: the components split over two
    host devices in a process of their own (:func:`device_rows`), its table written."""
    from experiments.run import main

    assert main(["bench", "stream", "--components", "300", "--scenes", "object", "--frames",
                 "4", "--sizes", "24", "--search", "kdtree", "--devices", "2",
                 "--out", str(tmp_path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    rows = {r["estep"]: r for r in out["rows"]}
    assert set(rows) == {"dense", "sparse"}
    row = rows["sparse"]
    assert row["frames"] == 4 and row["search"] == "kdtree" and row["components"] == 300
    assert row["padded"] >= row["points_per_frame"] > 0
    assert row["total_s"] >= row["setup_s"] + row["compile_s"]
    assert math.isfinite(row["s_per_frame"]) or row["compile_s"] > 0
    assert len(out["speedups"]) == 1 and out["profile"]
    names = {Path(f).name for f in out["files"]}
    assert {"bench_stream.csv", "bench_stream.md", "bench_stream_profile.csv",
            "bench_stream_devices.csv"} <= names
    (device,) = out["devices"]
    assert device["devices"] == 2 and device["components"] == 300 and device["frames"] == 4
    assert device["estep"] == "sparse" and device["padded"] >= device["points_per_frame"] > 0
    assert math.isfinite(device["s_per_frame"]) and device["s_per_frame"] > 0


def test_a_budget_bounds_the_points_of_every_frame():
    scene = object_scene(size=24, n_train=3, n_test=1, seed=0)
    row = stream_row(scene, _prior(scene, 200), "sparse", frames=3, search="kdtree",
                     budget_points=100)  # every 3rd pixel a side: at most 8 x 8
    assert row["budget"] == 100 and 0 < row["points_per_frame"] <= 64


def test_sensor_sized_frames_get_their_own_rows():
    cells = large_cells((640, 480), (20000, 100000), ("object", "room"), 60)
    assert cells == [((640, 480), "room", 100000, "sparse", 0, 10),
                     ((640, 480), "room", 100000, "sparse", LARGE_BUDGET, 10)]


def test_speedups_pair_sparse_with_dense():
    rows = [{"scene": "object", "components": 10, "estep": "dense", "s_per_frame": 2.0},
            {"scene": "object", "components": 10, "estep": "sparse", "s_per_frame": 0.5},
            {"scene": "room", "components": 10, "estep": "sparse", "s_per_frame": 0.5}]
    out = speedups(rows)
    assert len(out) == 1 and np.isclose(out[0]["sparse_over_dense"], 4.0)


def test_device_rows_refuse_an_uneven_split_before_starting_processes():
    with pytest.raises(ValueError, match="do not split evenly over \\[4\\] devices"):
        device_rows([1, 4], 402, "object", frames=2, size=24)


def test_a_gpu_run_writes_its_own_table(monkeypatch):
    """The committed CPU table is never overwritten by a run on another backend."""
    from experiments.benchmarks import bench_stream

    assert bench_stream.table_name() == "bench_stream"  # the CPU
    monkeypatch.setattr(bench_stream.jax, "default_backend", lambda: "gpu")
    assert bench_stream.table_name() == "bench_stream_gpu"
