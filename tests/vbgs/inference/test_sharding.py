"""Components sharded over 4 host CPU devices give the one-device posterior (to 1e-5)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from vbgs.inference.sharding import HOST_DEVICE_XLA_FLAGS, host_device_flags


@pytest.fixture(scope="module")
def sharded():
    root = Path(__file__).resolve().parents[3]
    path = os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")]))
    # the session's other XLA flags kept (tests/conftest.py: compiled without LLVM's passes)
    env = {**os.environ, "XLA_FLAGS": host_device_flags(4, os.environ.get("XLA_FLAGS", "")),
           "JAX_PLATFORMS": "cpu", "JAX_ENABLE_X64": "1", "PYTHONPATH": path}
    out = subprocess.run([sys.executable, str(Path(__file__).with_name("sharded_check.py"))],
                         capture_output=True, text=True, env=env, cwd=root, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("mode", ["prior-dense", "posterior-dense", "prior-sparse"])
def test_sharded_update_equals_one_device(sharded, mode):
    res = sharded[mode]
    assert res["devices_holding_means"] == 4
    for name in ("mean", "scale", "count", "colour", "elbo"):
        assert res[name] < 1e-5, (name, res)


def test_uneven_split_refused(sharded):
    assert sharded["uneven_refused"]


def test_host_device_flags_replace_the_count_and_keep_other_flags():
    flags = host_device_flags(2, "--xla_dump_to=/tmp/x --xla_force_host_platform_device_count=8")
    assert flags.split() == ["--xla_dump_to=/tmp/x", "--xla_force_host_platform_device_count=2",
                             *HOST_DEVICE_XLA_FLAGS]
