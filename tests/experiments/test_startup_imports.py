"""Start-up: a fit-image run imports only what it uses (each of these costs tens to
hundreds of milliseconds on every call of the command)."""

import json
import os
import subprocess
import sys
from pathlib import Path

NOT_FOR_A_FIT = ("optax", "pandas", "tabulate", "matplotlib", "tqdm", "dask", "onnxruntime",
                 "skimage.io", "vbgs.baseline", "experiments.sweep.cli",
                 "experiments.sweep.backends",
                 # a bundled photo comes resized from the cache; pixel grids need no
                 # KD-tree (vbgs.inference.grow.lattice_step)
                 "skimage.transform", "scipy.ndimage", "scipy.spatial")

CODE = f"""
import json, sys
from experiments.run import build_parser
build_parser("fit-image").parse_args(["fit-image", "--json"])
import experiments.cli.output, experiments.tasks.image_task, vbgs.compilation
print(json.dumps([m for m in {NOT_FOR_A_FIT!r} if m in sys.modules]))
"""


def test_fit_image_path_leaves_out_unused_packages():
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(root), os.environ.get("PYTHONPATH")]))}
    out = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True,
                         env=env, cwd=root, timeout=300, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_every_command_still_has_its_parser():
    from experiments.run import COMMANDS, build_parser

    parser = build_parser()
    assert parser.parse_args(["sweep", "--config", "quick"]).command == "sweep"
    assert parser.parse_args(["report", "results/ablations"]).command == "report"
    assert set(parser._subparsers._group_actions[0].choices) == set(COMMANDS)


def test_a_sweep_worker_sets_its_thread_limits_before_jax():
    """A local sweep worker is spawned into experiments.sweep.backends and limits XLA's
    threads there; that only works if nothing it imports has imported JAX already."""
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(root), os.environ.get("PYTHONPATH")]))}
    code = "import sys, experiments.sweep.backends; print('jax' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, cwd=root, timeout=300, check=True)
    assert out.stdout.strip().splitlines()[-1] == "False"
