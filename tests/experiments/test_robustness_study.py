"""The robustness study end to end on a tiny grid (32 px, 4 frames): the sweep's report
writes robustness.png and robustness.md beside cells.csv, and more Kinect noise costs
VBGS that takes the depth as exact held-out PSNR (4 x the noise: 2 dB)."""

import json

import pandas as pd
import pytest

from experiments.provenance import is_stamped_markdown
from experiments.run import main
from experiments.sweep.config import load_config
from experiments.sweep.robustness import condition, plot_robustness, robustness_table

TINY = """
name = "robustness-tiny"
[fixed]
task = "scene"
dataset = "object"
size = 32
frames = 4
n_test = 2
components = 300
seed = 0
simulate_sensor = "kinect"
method = "vbgs"
sensor = "exact"

[[grid]]
sensor_level = [0.0, 4.0]
sensor_holes = "none"

[[grid]]
sensor_level = 0.0
sensor_holes = "random:0.1"
"""


def test_the_committed_study_plans_both_axes_for_every_method():
    from experiments.sweep.cells import expand

    cells = [c.as_dict() for c in expand(load_config("experiments/configs/robustness.toml")).cells]
    lines = {(c["method"], c["sensor"]) for c in cells}
    assert lines == {("vbgs", "exact"), ("vbgs", "kinect"), ("gradient", "kinect")}
    for scene in ("object", "room"):
        for line in lines:
            mine = [c for c in cells if (c["method"], c["sensor"]) == line
                    and c["dataset"] == scene]
            noise = sorted(c["sensor_level"] for c in mine if c["sensor_holes"] == "none")
            holes = {c["sensor_holes"] for c in mine if c["sensor_level"] == 0}
            assert noise == [0.0, 0.5, 1.0, 2.0]
            assert holes == {"none", "random:0.02", "random:0.05", "random:0.1", "physical"}


def test_a_tiny_study_end_to_end(tmp_path, capsys):
    config = tmp_path / "tiny.toml"
    config.write_text(TINY)
    out = tmp_path / "out"
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["finished"] == 3 and summary["failed"] == 0
    assert str(out / "robustness.png") in summary["figures"]
    cells = pd.read_csv(out / "cells.csv")
    for column in ("psnr", "ssim", "depth_l1", "sensor_level", "sensor_holes",
                   "depth_sensor_holes"):
        assert cells[column].notna().all(), column
    png = (out / "robustness.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 20_000
    table = (out / "robustness.md").read_text()
    assert is_stamped_markdown(table)
    for column in ("noise 0", "noise 4", "random 10 %", "PSNR change"):
        assert column in table
    psnr = cells.set_index(["sensor_level", "sensor_holes"])["psnr"]
    # measured: 18.33 dB without noise, 16.35 dB at four times the Kinect's noise (the
    # depth taken as exact puts surfaces where the noise put the points)
    assert psnr[(4.0, "none")] < psnr[(0.0, "none")] - 1.0
    share = cells.set_index(["sensor_level", "sensor_holes"])["depth_sensor_holes"]
    assert 0.06 < share[(0.0, "random:0.1")] < 0.14 and share[(4.0, "none")] == 0.0


def test_conditions_are_named_for_a_reader():
    assert condition(0.5, "none") == "noise 0.5"
    assert condition(0.0, "random:0.05") == "random 5 %"
    assert condition(0.0, "physical") == "physical"
    assert condition(1.0, "sensor") == "noise 1, own holes"
    assert condition(2.0, "physical+random:0.1") == "noise 2, physical + random 10 %"


def test_nothing_to_report_without_a_sensor_axis(tmp_path):
    plain = pd.DataFrame({"dataset": ["object"], "method": ["vbgs"], "psnr": [20.0],
                          "simulate_sensor": ["exact"], "sensor_level": [1.0],
                          "sensor_holes": ["sensor"]})
    path, note = plot_robustness(plain, tmp_path / "r.png")
    assert path is None and "no cells vary" in note and not (tmp_path / "r.png").exists()
    assert robustness_table(plain) is None
    photos = pd.DataFrame({"task": ["image"], "dataset": ["astronaut"], "psnr": [25.0]})
    assert plot_robustness(photos, tmp_path / "r.png")[0] is None
    assert robustness_table(photos) is None
    with pytest.raises(ValueError, match="unknown holes"):
        condition(0.0, "edges")
