"""``python -m experiments.run front``: every method's row, the CSV's columns, the
Pareto front and the plot, on a tiny scene."""

import json

import numpy as np
import pandas as pd
import pytest

from experiments.front import COLUMNS, parse_counts, pareto
from experiments.run import main


def test_pareto_keeps_the_rows_nothing_beats():
    cost = np.array([1.0, 2.0, 3.0, 2.0, 5.0])
    score = np.array([10.0, 12.0, 11.0, 12.0, 13.0])
    # row 2 is slower and worse than row 1; rows 1 and 3 tie (neither dominates)
    assert pareto(cost, score).tolist() == [True, True, False, True, True]


def test_step_lists_are_refused_in_words():
    assert parse_counts("10, 20", "--steps") == (10, 20)
    with pytest.raises(ValueError, match="positive integers"):
        parse_counts("10,0", "--polish-steps")


@pytest.mark.slow  # 31 s of compiling five learners; the image front keeps `front` in the default run
def test_front_on_a_tiny_scene(tmp_path, capsys):
    out = tmp_path / "front"
    code = main(["front", "--scene", "object", "--size", "16", "--components", "100",
                 "--frames", "3", "--test-views", "1", "--polish-steps", "2",
                 "--gradient-steps", "3", "--replays", "fifo:2", "--steps-per-frame", "1",
                 "--out", str(out), "--json"])
    assert code == 0
    captured = capsys.readouterr()
    assert "front [5/5]" in captured.err  # progress on stderr
    files = json.loads(captured.out.strip().splitlines()[-1])["files"]
    assert str(out / "object.png") in files and (out / "object.png").stat().st_size > 10_000
    table = pd.read_csv(out / "object.csv")
    assert set(COLUMNS) | {"on_front"} <= set(table.columns)
    assert sorted(zip(table.method, table.protocol, table.replay, strict=True)) == sorted([
        ("vbgs", "continual", "none"), ("vbgs-polish", "static", "none"),
        ("gradient", "static", "none"), ("gradient", "continual", "fifo:2"),
        ("vbgs-polish", "continual", "fifo:2")])
    assert table.loc[table.protocol == "static", "steps"].tolist() == [2, 3]
    frame_bytes = 16 * 16 * 4 * 4  # rgb + depth, float32
    assert (table.loc[table.replay == "fifo:2", "replay_bytes"] == 2 * frame_bytes).all()
    assert (table.wall_seconds > 0).all() and table.psnr.between(5, 60).all()
    front = table[table.on_front]
    assert len(front) >= 1
    for _, row in front.iterrows():  # nothing at least as fast is better
        rivals = table[(table.wall_seconds <= row.wall_seconds) & (table.psnr > row.psnr)]
        assert rivals.empty
    assert not table[~table.on_front].empty or len(table) == len(front)


def test_front_refuses_several_scene_component_counts(capsys):
    code = main(["front", "--scene", "object", "--components", "100,200", "--json"])
    assert code == 2
    assert "one count" in capsys.readouterr().err


def test_image_front_times_warm_fits(tmp_path):
    out = tmp_path / "img"
    assert main(["front", "--image", "astronaut", "--size", "16", "--components", "20",
                 "--gradient-steps", "5", "--iters", "2", "--out", str(out)]) == 0
    table = pd.read_csv(out / "astronaut.csv")
    assert table.method.tolist() == ["vbgs", "gradient"]
    assert table.steps.tolist() == [2, 5] and (table.protocol == "image").all()
    assert (table.compile_seconds >= 0).all() and (out / "astronaut.png").exists()
