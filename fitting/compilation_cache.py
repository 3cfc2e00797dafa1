"""JAX's persistent compilation cache for the fitting commands.

A fit compiles its simulator, Jacobian and optimiser once per shape of problem (seconds to tens
of seconds on a laptop's cores); with the cache on, a second run of the same command on files
of the same shapes loads the compiled code from disk instead. The cache lives in
`$HERTZCHAIN_CACHE/jax` (default `~/.cache/hertzchain/jax`, or under `$XDG_CACHE_HOME`), next
to the native kernel's builds (`hertzchain.native`). Turn it off with the commands'
`--no-compile-cache` or the environment variable `HERTZCHAIN_NO_COMPILE_CACHE=1`; delete the
folder to clear it.
"""

from __future__ import annotations

import os
from pathlib import Path

from hertzchain.native import cache_dir as hertzchain_cache_dir

# Environment variable that turns the cache off (any value but "", "0", "false", "no").
DISABLE_VARIABLE = "HERTZCHAIN_NO_COMPILE_CACHE"
# Compilations shorter than this are not kept: none (a fit runs about 150 small ones, 9 s in all
# on a loaded machine, each loaded from the cache in milliseconds).
MIN_COMPILE_SECONDS = 0.0


def cache_folder() -> Path:
    """The folder of the compiled programs."""
    return hertzchain_cache_dir() / "jax"


def enable_compilation_cache(enabled: bool = True) -> Path | None:
    """Point JAX's persistent compilation cache at `cache_folder()` (unless `enabled` is
    False or `HERTZCHAIN_NO_COMPILE_CACHE` is set); returns the folder, or None when off."""
    if not enabled or os.environ.get(DISABLE_VARIABLE, "").strip().lower() not in ("", "0", "false", "no"):
        return None
    import jax

    folder = cache_folder()
    folder.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return folder


def jax_cache_on() -> bool:
    """Whether JAX's persistent compilation cache is set up in this process."""
    import jax

    return bool(jax.config.jax_compilation_cache_dir)
