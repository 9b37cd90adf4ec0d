"""Persistent compilation cache settings and the compile timer."""

from pathlib import Path

import jax
import jax.numpy as jnp

from vbgs import compilation


def test_cache_dir_default_opt_out_and_override(monkeypatch, tmp_path):
    monkeypatch.delenv("VBGS_NO_COMPILE_CACHE", raising=False)
    monkeypatch.delenv("VBGS_COMPILE_CACHE", raising=False)
    monkeypatch.delenv("VBGS_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert compilation.cache_dir() == tmp_path / "vbgs" / "jax"
    monkeypatch.setenv("VBGS_CACHE_DIR", str(tmp_path / "moved"))
    assert compilation.cache_root() == tmp_path / "moved"
    assert compilation.cache_dir() == tmp_path / "moved" / "jax"
    monkeypatch.setenv("VBGS_COMPILE_CACHE", str(tmp_path / "elsewhere"))
    assert compilation.cache_dir() == Path(tmp_path / "elsewhere")
    monkeypatch.setenv("VBGS_NO_COMPILE_CACHE", "1")
    assert compilation.cache_dir() is None
    assert compilation.enable_persistent_cache() is None


def test_compile_timer_sees_compiles_not_cached_calls():
    f = jax.jit(lambda x: jnp.sin(x) * 3.0 + x**2)
    x = jnp.arange(7.0)
    with compilation.CompileTimer() as first:
        f(x).block_until_ready()
    with compilation.CompileTimer() as second:
        f(x).block_until_ready()
    assert first.seconds > 0
    assert second.seconds == 0
