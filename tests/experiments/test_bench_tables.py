"""Benchmark tables: the command and settings in the file, dropped overlaps marked."""

import pandas as pd

from experiments.benchmarks.bench import write_table


def test_rows_that_dropped_overlaps_are_marked(tmp_path):
    rows = [{"size": 128, "splats": 50000, "forward_s": 0.13, "dropped": 31580},
            {"size": 128, "splats": 10000, "forward_s": 0.05, "dropped": 0}]
    csv, md = write_table(rows, tmp_path, "bench_raster", command="python -m x bench raster")
    frame = pd.read_csv(csv)
    assert frame["exact"].tolist() == [False, True]
    text = md.read_text()
    assert "Command: `python -m x bench raster`" in text
    assert "exact = False dropped splat-tile overlaps" in text
    assert " 31580 " in text and " 50000 " in text  # integers, not 3.158e+04 and 5e+04
    assert "e+04" not in text


def test_either_dropped_column_marks_a_row_and_clean_tables_have_no_note(tmp_path):
    rows = [{"components": 20000, "dense_dropped": 0, "sparse_dropped": 3},
            {"components": 50000, "dense_dropped": 0, "sparse_dropped": 0}]
    csv, md = write_table(rows, tmp_path, "bench_estep", settings={"size": 128})
    frame = pd.read_csv(csv)
    assert frame["exact"].tolist() == [False, True] and (frame["size"] == 128).all()
    assert "Settings: size = 128" in md.read_text()
    csv, md = write_table([{"components": 1, "dropped": 0}], tmp_path, "clean")
    assert "not exact" not in md.read_text() and pd.read_csv(csv)["exact"].all()
    csv, md = write_table([{"size": 16, "seconds": 0.5}], tmp_path, "plain")
    assert "exact" not in pd.read_csv(csv) and "Command" not in md.read_text()
