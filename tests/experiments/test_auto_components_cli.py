"""``--components auto`` through fit-scene and the sweep: the K chosen, and refusals."""

import json

from experiments.run import main
from experiments.sweep.cells import expand
from experiments.sweep.config import ConfigError, parse_config

TINY = ["--scene", "object", "--frames", "4", "--test-views", "1", "--size", "32"]


def test_fit_scene_auto_reports_the_k_it_chose(capsys):
    assert main(["fit-scene", *TINY, "--components", "auto", "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    # measured 354 components chosen, 354 drawn, capacity 4096 (one bucket), 20.57 dB:
    # no split (4 frames at 32 px show no cell often enough for a child to pay for its
    # parameters, vbgs.mapping.splits; the per-frame colour rule before it made 866, 20.44)
    assert r["components"] == "auto" and not r["components_capped"]
    assert 300 < r["components_chosen"] < 450 and r["components_capacity"] == 4096
    assert 0 < r["components_used"] <= r["components_chosen"]
    assert r["psnr"] > 19.5


def test_fit_scene_refuses_bad_component_counts(capsys):
    for value, words in (("auto:0", "auto:MAX"), ("abc", "'auto'"), ("0", "positive integer")):
        assert main(["fit-scene", *TINY, "--components", value]) == 2
        err = capsys.readouterr().err
        assert "components" in err and words in err, err
    assert main(["fit-scene", *TINY, "--components", "auto", "--method", "gradient"]) == 2
    assert "takes a number of components" in capsys.readouterr().err


def _grid(components):
    return {"name": "t", "grid": [{"task": ["scene", "image"], "dataset": ["object"],
                                   "method": ["vbgs", "gradient"],
                                   "components": components}]}


def test_sweep_accepts_auto_for_vbgs_scene_cells_only():
    plan = expand(parse_config(_grid(["auto", "auto:9000", 500])))
    cells = [c.as_dict() for c in plan.cells]
    auto = [c for c in cells if isinstance(c["components"], str)]
    assert {c["components"] for c in auto} == {"auto", "auto:9000"}
    assert all(c["task"] == "scene" and c.get("method", "vbgs") == "vbgs" for c in auto)
    assert any("components = \"auto\" is chosen by VBGS" in s.reason for s in plan.skipped)
    for bad, words in (("auto:0", "auto:MAX"), ("abc", "\"auto\""), (0, "positive integer")):
        try:
            parse_config(_grid([bad]))
        except ConfigError as err:
            assert "grid[0].components" in str(err) and words in str(err), err
        else:
            raise AssertionError(f"{bad!r} was accepted")


def test_tables_and_plot_show_the_k_auto_chose(tmp_path):
    import pandas as pd

    from experiments.sweep.plots import plot_psnr_vs_components
    from experiments.sweep.report import summary_table

    df = pd.DataFrame([
        {"task": "scene", "dataset": "object", "method": "vbgs", "components": k,
         "psnr": p, "components_used": u, "components_chosen": c}
        for k, p, u, c in (("auto", 24.0, 9009, 9012), (5000, 23.8, 4925, None),
                           (20000, 25.7, 19842, None))])
    table, _ = summary_table(df, ["dataset", "components"])
    assert "K chosen" in table and "9012" in table and "| auto " in table
    path, why = plot_psnr_vs_components(df, ["method"], tmp_path / "k.png")
    assert why == "" and path.stat().st_size > 5_000
