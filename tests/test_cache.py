"""The persistent compilation cache switch: where it points, and the opt-out."""

import jax
import pytest

from sintercond._cache import enable_compilation_cache


@pytest.fixture
def restore_config():
    keys = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs",
            "jax_persistent_cache_min_entry_size_bytes")
    saved = {key: getattr(jax.config, key) for key in keys}
    yield
    for key, value in saved.items():
        jax.config.update(key, value)


def test_cache_directory_from_argument_and_environment(tmp_path, monkeypatch, restore_config):
    monkeypatch.setenv("SINTERCOND_COMPILATION_CACHE", "1")
    monkeypatch.setenv("SINTERCOND_CACHE_DIR", str(tmp_path / "env"))
    assert enable_compilation_cache() == tmp_path / "env"
    assert jax.config.jax_compilation_cache_dir == str(tmp_path / "env") and (tmp_path / "env").is_dir()
    assert jax.config.jax_persistent_cache_min_compile_time_secs < 1.0  # our steps compile in < 1 s
    assert enable_compilation_cache(tmp_path / "arg") == tmp_path / "arg"
    monkeypatch.delenv("SINTERCOND_CACHE_DIR")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert enable_compilation_cache() == tmp_path / ".cache" / "sintercond" / "jax"


@pytest.mark.parametrize("off", ["0", "false", "OFF"])
def test_opt_out(tmp_path, monkeypatch, restore_config, off):
    monkeypatch.setenv("SINTERCOND_COMPILATION_CACHE", off)
    before = jax.config.jax_compilation_cache_dir
    assert enable_compilation_cache(tmp_path) is None
    assert jax.config.jax_compilation_cache_dir == before and not any(tmp_path.iterdir())


def test_cli_default_is_off_on_the_cpu_and_forced_by_the_environment(monkeypatch):
    """On the CPU jaxlib 0.10.1 logs a false SIGILL warning per cached executable: the CLI leaves the cache off
    there unless asked."""
    from sintercond._cache import cache_by_default

    monkeypatch.delenv("SINTERCOND_COMPILATION_CACHE", raising=False)
    assert cache_by_default() == (jax.default_backend() != "cpu")
    monkeypatch.setenv("SINTERCOND_COMPILATION_CACHE", "1")
    assert cache_by_default()
    monkeypatch.setenv("SINTERCOND_COMPILATION_CACHE", "0")
    assert not cache_by_default()
