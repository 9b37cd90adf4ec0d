"""``--components auto`` through fit-scene and the sweep: the K chosen, and refusals."""

import json

from experiments.run import main
from experiments.sweep.cells import expand
from experiments.sweep.config import ConfigError, parse_config

TINY = ["--scene", "object", "--frames", "4", "--test-views", "1", "--size", "32"]


def test_fit_scene_auto_reports_the_k_it_chose(capsys):
    assert main(["fit-scene", *TINY, "--components", "auto", "--json"]) == 0
    r = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    # measured 645 components chosen, 645 drawn, capacity 4096 (one bucket), 20.45 dB
    assert r["components"] == "auto" and not r["components_capped"]
    assert 500 < r["components_chosen"] < 800 and r["components_capacity"] == 4096
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
    for bad, words in (("auto:0", "auto:MAX"), ("abc", "'auto'"), (0, "positive integer")):
        try:
            parse_config(_grid([bad]))
        except ConfigError as err:
            assert "grid[0].components" in str(err) and words in str(err), err
        else:
            raise AssertionError(f"{bad!r} was accepted")
