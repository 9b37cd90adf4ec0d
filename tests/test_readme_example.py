"""The README's library example (its first ```python block that uses ``vbgs.mapping``)
imports only ``vbgs`` and prints the held-out PSNR that ``fit-scene --json`` reports for
the same settings (the committed ``results/example/object.json`` and a live run, both in
the slow run: ``python -m pytest -q -m slow``)."""

import ast
import contextlib
import io
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def readme_example() -> str:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    found = [b for b in blocks if "mapping" in b and "vbgs" in b]
    assert found, "the README has no ```python block that uses vbgs.mapping"
    return found[0]


def example_psnr() -> float:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(readme_example(), "README example", "exec"), {"__name__": "__readme__"})
    last = out.getvalue().strip().splitlines()[-1]
    match = re.search(r"([0-9]+\.[0-9]+) dB", last)
    assert match, f"the example's last line gives no PSNR: {last!r}"
    return float(match.group(1))


def test_the_example_imports_vbgs_only():
    tree = ast.parse(readme_example())
    roots = {alias.name.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.Import)
             for alias in node.names}
    roots |= {node.module.split(".")[0] for node in ast.walk(tree)
              if isinstance(node, ast.ImportFrom)}
    assert "vbgs" in roots and "experiments" not in roots and "depth" not in roots
    assert len(readme_example().strip().splitlines()) <= 16


def test_the_committed_record_has_the_examples_settings():
    record = json.loads((ROOT / "results/example/object.json").read_text())
    assert (record["scene"], record["size"], record["components"], record["frames"],
            record["seed"], record["init"]) == ("object", 128, 20000, 60, 0, "stream")


# Slow: a 128 px, 60 frame, 20k component stream (the default run's largest scene fit).
# The default run keeps fit-scene end to end at a tiny size (test_fit_scene_cli) and the
# mapper's streaming loop (tests/vbgs/mapping); this runs the README's own code.
@pytest.mark.slow
def test_the_example_reproduces_fit_scene_and_its_record(capsys):
    from experiments.run import main

    record = json.loads((ROOT / "results/example/object.json").read_text())
    example = example_psnr()
    assert example == pytest.approx(record["psnr"], abs=0.01)
    assert main(["fit-scene", "--scene", "object", "--json"]) == 0
    live = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["psnr"]
    assert example == pytest.approx(live, abs=0.01)
