"""The fitting commands' persistent compilation cache: where it lives and how it is turned off."""

import jax

from fitting.compilation_cache import enable_compilation_cache


def test_cache_folder_follows_hertzchain_cache_and_the_switches(tmp_path, monkeypatch):
    before = jax.config.jax_compilation_cache_dir
    try:
        monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path))
        monkeypatch.delenv("HERTZCHAIN_NO_COMPILE_CACHE", raising=False)
        assert enable_compilation_cache(False) is None
        monkeypatch.setenv("HERTZCHAIN_NO_COMPILE_CACHE", "1")
        assert enable_compilation_cache() is None
        monkeypatch.setenv("HERTZCHAIN_NO_COMPILE_CACHE", "0")
        folder = enable_compilation_cache()
        assert folder == tmp_path / "jax" and folder.is_dir()
        assert jax.config.jax_compilation_cache_dir == str(folder)
    finally:
        jax.config.update("jax_compilation_cache_dir", before)
