"""A sweep on scenes that change: tables.md gains the changed / unchanged pixels' PSNR and
the unchanged pixels' retention, and changing.png draws them per learner. No cell is
computed here: records are stored by hand."""

import json

import pandas as pd

from experiments.sweep.cells import store_record
from experiments.sweep.plots import _learner
from experiments.sweep.report import write_report


def _record(key: str, settings: dict, changed: float, unchanged: float) -> dict:
    result = {"psnr": (changed + unchanged) / 2, "ssim": 0.5, "components_used": 100,
              "seconds": 1.0, "replay_bytes": 0, "psnr_changed": changed,
              "psnr_unchanged": unchanged, "unchanged_retention": -0.5,
              "psnr_first_state": 15.0}
    return {"key": key, "status": "ok", "version": "test", "result": result,
            "settings": {"task": "scene", "dataset": "object-change", "seed": 0, **settings}}


def test_a_changing_sweep_reports_changed_and_unchanged_pixels(tmp_path):
    cells = [({"method": "vbgs", "evidence.forget_after": 6}, 20.0, 29.0),
             ({"method": "vbgs", "evidence.forget_after": 0}, 11.0, 28.0),
             ({"method": "gradient", "replay": "fifo:8"}, 14.0, 24.0)]
    keys = []
    for i, (settings, changed, unchanged) in enumerate(cells):
        keys.append(f"{i:016x}")
        store_record(tmp_path, _record(keys[-1], settings, changed, unchanged))
    (tmp_path / "plan.json").write_text(json.dumps(
        {"name": "t", "cells": [{"key": k} for k in keys]}))
    summary = write_report(tmp_path)
    tables = (tmp_path / "tables.md").read_text()
    for column in ("changed px (dB)", "unchanged px (dB)", "unchanged retention (dB)",
                   "first state (dB)"):
        assert column in tables
    assert (tmp_path / "changing.png").is_file()
    assert str(tmp_path / "changing.png") in summary["figures"]


def test_a_learner_is_named_in_words():
    cols = ["method", "replay", "from_frame", "evidence.forget_after",
            "evidence.recolour_sigmas", "evidence.recolour_gate"]
    row = pd.Series({"method": "vbgs", "replay": "none", "from_frame": 0,
                     "evidence.forget_after": 6.0, "evidence.recolour_sigmas": 4.0,
                     "evidence.recolour_gate": 0.0})
    assert _learner(row, cols) == "VBGS, forget after 6, colour 4 sigmas, no colour gate"
    row = pd.Series({"method": "vbgs", "replay": "none", "from_frame": 0,
                     "evidence.forget_after": 6.0})  # the defaults: nothing more to say
    assert _learner(row, cols) == "VBGS, forget after 6"
    row = pd.Series({"method": "vbgs", "replay": "none", "from_frame": 15,
                     "evidence.forget_after": 0, "evidence.recolour_sigmas": 0})
    assert _learner(row, cols) == "VBGS, fresh map from frame 15, no forgetting, no colour"
    row = pd.Series({"method": "gradient", "replay": "fifo:8", "from_frame": 0,
                     "evidence.forget_after": float("nan")})
    assert _learner(row, cols) == "gradient, replay fifo:8"


def test_a_sweep_without_changing_scenes_draws_no_change_bars(tmp_path):
    from experiments.sweep.plots import plot_changes

    df = pd.DataFrame([{"task": "scene", "dataset": "object", "psnr": 20.0}])
    path, note = plot_changes(df, ["task", "dataset"], tmp_path / "changing.png")
    assert path is None and "psnr_changed" in note



def test_a_setting_only_some_cells_name_tells_their_lines_apart():
    """A fresh map (``from_frame = 15``) beside the map whose settings are the same but
    leave from_frame unset: two lines, two labels. pandas' string conversion keeps a
    missing value missing, and counting distinct values without it took from_frame for
    a constant: both forgetting curves were drawn as one zigzag line."""
    from experiments.sweep.plots import _labels, _line_columns

    base = {"task": "scene", "dataset": "object-change", "method": "vbgs", "seed": 0}
    df = pd.DataFrame([base, {**base, "from_frame": 15}])
    cols = _line_columns(df, list(df.columns))
    assert cols == ["from_frame"]
    assert _labels(df, cols).tolist() == ["", "from_frame=15"]


def test_a_setting_left_at_its_default_in_some_cells_of_a_method_is_not_said_fixed():
    """The changing study's default VBGS row leaves ``evidence.recolour_gate`` unset (its
    default) beside a row that sets it to 0: the table keeps the column, and does not say
    the setting is 0 for every row; a setting only one method reads, set in all its cells,
    is still said once."""
    from experiments.sweep.report import summary_table

    df = pd.DataFrame([
        {"method": "vbgs", "evidence.recolour_gate": None, "steps": None, "psnr": 20.0},
        {"method": "vbgs", "evidence.recolour_gate": 0.0, "steps": None, "psnr": 21.0},
        {"method": "gradient", "evidence.recolour_gate": None, "steps": 50, "psnr": 19.0},
    ])
    table, fixed = summary_table(df, ["method", "evidence.recolour_gate", "steps"])
    assert "evidence.recolour_gate" not in fixed and "evidence.recolour_gate" in table
    assert fixed == {"steps": 50}
