"""What a user's command compiles: short end-to-end runs at XLA's default settings.

The default test run compiles with XLA:CPU's older emitters and no optimisation passes
(``tests/conftest.py``); a user's command does not. These tests are marked ``slow`` (the
default run leaves them out) and ``users``, and CI runs them apart at XLA's default:
``python -m pytest -q -m users`` (``.ci/run``). They run the README's library example
(its PSNR is the committed record's) and ``fit-scene`` on each synthetic scene kind at a
small size.
"""

import importlib.util
import json
import math
import os
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.users]

HERE = Path(__file__).resolve().parent


def _module(name: str):
    spec = importlib.util.spec_from_file_location(f"_users_{name}", HERE / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_session_compiles_at_xlas_default():
    fast = _module("conftest").FAST_COMPILE_FLAGS
    assert not set(fast) & set(os.environ.get("XLA_FLAGS", "").split())


def test_the_readme_example_at_xlas_default():
    readme = _module("test_readme_example")
    record = json.loads((readme.ROOT / "results/example/object.json").read_text())
    assert readme.example_psnr() == pytest.approx(record["psnr"], abs=0.01)


# 32 px, 12 frames, 1000 components, 2 test views; measured at XLA's default: object
# 20.12 dB, room 19.72, walk 19.83. Floors 1.5 dB under each.
FLOORS = {"object": 18.6, "room": 18.2, "walk": 18.3}


@pytest.mark.parametrize("scene", sorted(FLOORS))
def test_fit_scene_at_xlas_default(scene, capsys):
    from experiments.run import main

    assert main(["fit-scene", "--scene", scene, "--size", "32", "--frames", "12",
                 "--components", "1000", "--test-views", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert math.isfinite(result["psnr"]) and result["psnr"] > FLOORS[scene], result["psnr"]
    assert result["components_used"] > 0
