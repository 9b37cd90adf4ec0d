"""Sweep tables show LPIPS where cells report it, and no LPIPS column where none does."""

import json

from experiments.run import main


def test_tables_show_lpips_only_when_cells_report_it(tmp_path, capsys):
    config = tmp_path / "c.toml"
    config.write_text('name = "lp"\n[fixed]\ntask = "image"\nsize = 16\niters = 1\n'
                      '[[grid]]\ndataset = "astronaut"\ncomponents = 20\ninit = "data"\n'
                      'seed = [0, 1]\n')
    out = tmp_path / "res"
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--strict"]) == 0
    assert "LPIPS" not in (out / "tables.md").read_text()
    for i, path in enumerate(sorted((out / "cells").glob("*.json"))):
        record = json.loads(path.read_text())
        record["result"]["lpips"] = 0.25 + 0.5 * i  # as a task with the lpips extra reports
        path.write_text(json.dumps(record))
    capsys.readouterr()
    assert main(["report", str(out)]) == 0
    tables = (out / "tables.md").read_text()
    assert "| LPIPS " in tables and "0.500 ± 0.354" in tables  # mean ± std over the seeds
