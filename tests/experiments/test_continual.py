"""The continual-learning matrix and its metrics: hand-made matrices with known answers,
the segments of a stream, fit-scene's JSON end to end and the sweep's CSV and heat-map."""

import json

import numpy as np
import pandas as pd
import pytest

from experiments.tasks.continual import (
    Segments,
    average_final_psnr,
    backward_transfer,
    check_segments,
    continual_scores,
    forgetting,
    segment_ends,
    stream_segments,
)
from experiments.run import main
from experiments.sweep.cl_report import plot_cl_matrices, write_cl_matrix
from vbgs.data.synthetic import make_scene

# rows: after segment i; columns: segment j's views
R = [[20.0, 10.0, 8.0],
     [23.0, 22.0, 9.0],
     [17.0, 21.0, 24.0]]


def test_metrics_of_a_hand_made_matrix():
    assert average_final_psnr(R) == pytest.approx((17 + 21 + 24) / 3)
    # j=0: best before the end max(20, 23) = 23, at the end 17 -> 6; j=1: 22 - 21 = 1
    assert forgetting(R) == pytest.approx((6 + 1) / 2)
    # j=0: 17 - 20 = -3; j=1: 21 - 22 = -1 (the peak after learning is not the reference)
    assert backward_transfer(R) == pytest.approx((-3 - 1) / 2)
    # a map that only gets better: forgetting is negative, backward transfer positive
    better = [[20.0, 5.0], [21.5, 19.0]]
    assert forgetting(better) == pytest.approx(-1.5)
    assert backward_transfer(better) == pytest.approx(1.5)
    # the entries above the diagonal (segments not seen yet) change no metric
    future = np.array(R)
    future[np.triu_indices(3, 1)] = 99.0
    assert (forgetting(future), backward_transfer(future)) == (forgetting(R),
                                                              backward_transfer(R))


def test_record_and_its_json_fields():
    segments = Segments((4, 7, 10), ((0,), (1, 2), (2,)))
    scores = continual_scores(segments, R, seconds=0.5)
    d = scores.to_dict()
    assert d["cl_matrix"] == R and d["cl_segment_ends"] == [4, 7, 10]
    assert d["cl_segment_views"] == [[0], [1, 2], [2]]
    assert d["cl_forgetting"] == pytest.approx(3.5) and d["cl_seconds"] == 0.5
    with pytest.raises(ValueError, match="3 x 3"):
        continual_scores(segments, R[:2], seconds=0.0)
    # a row averages each segment's views; only inner segment ends render
    assert segments.row({0: 10.0, 1: 20.0, 2: 30.0}) == [10.0, 25.0, 30.0]
    assert segments.views_at(4) == [0, 1, 2] and segments.views_at(5) == []
    assert segments.views_at(10) == []  # the last row is the final evaluation's


def test_segments_of_a_stream():
    assert segment_ends(10, 3) == (4, 7, 10)
    assert segment_ends(6, 2) == (3, 6)
    for bad in (1, -1, 2.0, True):
        with pytest.raises(ValueError, match="cl_segments"):
            check_segments(bad)
    with pytest.raises(ValueError, match="more than the 3 training frames"):
        segment_ends(3, 4)
    # the walk's test views cover its whole path in stretches: the first segment's
    # views are those near its start, the last's those near its end
    scene = make_scene("walk", size=8, n_train=8, n_test=4, seed=0)
    segments = stream_segments(scene, np.arange(8), 2)
    assert segments.ends == (4, 8)
    xs = [f.camera.position[0] for f in scene.test]
    assert all(views for views in segments.views)
    assert max(xs[v] for v in segments.views[0]) < min(xs[v] for v in segments.views[1])


def test_fit_scene_json_has_the_matrix(capsys):
    tiny = ["fit-scene", "--scene", "walk", "--components", "600", "--frames", "6",
            "--test-views", "4", "--size", "32", "--json"]
    assert main([*tiny, "--cl-segments", "2"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    matrix = np.asarray(r["cl_matrix"])
    assert matrix.shape == (2, 2) and np.isfinite(matrix).all()
    assert r["cl_segments"] == 2 and r["cl_segment_ends"] == [3, 6]
    # measured: [[16.12, 13.55], [16.10, 15.11]] dB; the background alone scores ~9 dB
    assert matrix.min() > 12.0
    assert r["cl_avg_final_psnr"] == pytest.approx(matrix[-1].mean())
    assert r["cl_backward_transfer"] == pytest.approx(matrix[1, 0] - matrix[0, 0])
    assert r["cl_forgetting"] == pytest.approx(matrix[0, 0] - matrix[1, 0])
    assert r["cl_seconds"] > 0


def test_cl_segments_refused_where_it_does_not_apply(capsys):
    tiny = ["fit-scene", "--scene", "object", "--size", "32", "--frames", "4"]
    assert main([*tiny, "--method", "gradient", "--protocol", "static", "--cl-segments"]) == 2
    assert "--cl-segments measures the matrix along a stream" in capsys.readouterr().err
    assert main([*tiny, "--cl-segments", "1"]) == 2
    assert "cl_segments must be 0" in capsys.readouterr().err
    assert main([*tiny, "--cl-segments", "5"]) == 2
    assert "more than the 4 training frames" in capsys.readouterr().err


def _record(key, method, replay, seed, matrix):
    segments = Segments(tuple(range(3, 3 * len(matrix) + 1, 3)),
                        tuple((j,) for j in range(len(matrix))))
    result = continual_scores(segments, matrix, 0.1).to_dict()
    return {"key": key, "status": "ok", "result": result,
            "settings": {"task": "scene", "dataset": "walk", "method": method,
                         "replay": replay, "seed": seed, "cl_segments": len(matrix)}}


def test_sweep_csv_and_heat_map(tmp_path):
    flat = [[20.0, 12.0], [20.0, 21.0]]
    records = [_record("a", "vbgs", "none", 0, flat), _record("b", "vbgs", "none", 1, flat),
               _record("c", "gradient", "none", 0, [[22.0, 9.0], [15.0, 23.0]]),
               {"key": "d", "status": "failed", "settings": {"task": "scene"}}]
    path, _ = write_cl_matrix(records, tmp_path / "cl_matrix.csv")
    rows = pd.read_csv(path)
    assert len(rows) == 3 * 4 and set(rows["key"]) == {"a", "b", "c"}
    c = rows[rows.key == "c"].set_index(["after_segment", "segment"])["psnr"]
    assert c[(1, 0)] == 15.0 and c[(0, 1)] == 9.0
    assert list(rows[rows.key == "a"]["seen"]) == [True, False, True, True]
    png, _ = plot_cl_matrices(records, tmp_path / "cl_matrix.png")
    assert png.stat().st_size > 10_000
    assert plot_cl_matrices(records[-1:], tmp_path / "none.png")[0] is None
    assert write_cl_matrix([], tmp_path / "none.csv")[0] is None


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_gradient_without_replay_forgets_more_than_vbgs(seed):
    """Walk, 32 px, 8 frames in 2 segments: measured forgetting 0.76 / 0.37 dB for the
    gradient learner without replay against -0.32 / -0.25 dB for VBGS (seeds 0 / 1)."""
    from experiments.tasks.scene_task import SceneTask, run_scene

    def cl_forgetting(method):
        task = SceneTask(scene="walk", method=method, components=600, frames=8, n_test=4,
                         size=32, seed=seed, cl_segments=2)
        return run_scene(task).continual.forgetting

    assert cl_forgetting("gradient") > cl_forgetting("vbgs") + 0.3
