"""Process-wide runtime settings: the on-disk compilation cache."""

import jax

from hamjax._runtime import use_compilation_cache


def test_compilation_cache_folder_and_opt_out(tmp_path, monkeypatch):
    before = jax.config.jax_compilation_cache_dir
    try:
        monkeypatch.setenv("HAMJAX_CACHE_DIR", "off")
        use_compilation_cache()
        assert jax.config.jax_compilation_cache_dir == before
        monkeypatch.setenv("HAMJAX_CACHE_DIR", str(tmp_path / "xla"))
        use_compilation_cache()
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "xla")
        assert (tmp_path / "xla").is_dir()
        monkeypatch.delenv("HAMJAX_CACHE_DIR")
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        use_compilation_cache()
        assert (tmp_path / "xdg" / "hamjax" / "xla").is_dir()
    finally:
        jax.config.update("jax_compilation_cache_dir", before)
