"""Importing vbgs turns off XLA:CPU's concurrency-optimised scheduler (a posterior
stream hung with it on a 2-core CPU; see vbgs/__init__.py), and leaves a user's own
setting alone."""

import json
import os
import subprocess
import sys

import vbgs


def _flags_after_import(xla_flags: str | None) -> str:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    code = ("import os, json, vbgs.inference.model, jax; jax.numpy.zeros(1).block_until_ready(); "
            "print(json.dumps(os.environ.get('XLA_FLAGS')))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_adds_the_flag_in_a_fresh_process():
    assert _flags_after_import(None) == vbgs.CPU_SCHEDULER_FLAG
    flags = _flags_after_import("--xla_cpu_multi_thread_eigen=false")
    assert flags.split() == ["--xla_cpu_multi_thread_eigen=false", vbgs.CPU_SCHEDULER_FLAG]


def test_a_users_own_scheduler_setting_is_kept():
    mine = "--xla_cpu_enable_concurrency_optimized_scheduler=true"
    assert _flags_after_import(mine) == mine
    env = {"XLA_FLAGS": mine}
    vbgs.schedule_cpu_ops_in_sequence(env)
    assert env == {"XLA_FLAGS": mine}
