"""JAX's persistent compilation cache for socbjax programs: :func:`enable_compilation_cache`.

The first solve of a network topology compiles (seconds in 2D, tens of seconds for large 3D
networks); with the cache on, a later process with the same topology, settings and versions
loads the compiled program from disk instead.  The command line and the test suite turn it
on; a library import does not (it is the user's choice).
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

__all__ = ["enable_compilation_cache", "CACHE_ENV"]

CACHE_ENV = "SOCBJAX_CACHE_DIR"
_OFF = ("", "0", "off", "none", "false", "no")


def enable_compilation_cache(path: str | os.PathLike | None = None, *, min_compile_time_secs: float = 0.5) -> Path | None:
    """Store compiled programs under ``path`` and reuse them across processes.

    ``path`` defaults to ``$SOCBJAX_CACHE_DIR``, else ``~/.cache/socbjax/jax``.  Setting
    ``SOCBJAX_CACHE_DIR=off`` (or ``0``/``none``) disables the cache; a directory already
    configured for JAX (``JAX_COMPILATION_CACHE_DIR`` / ``jax_compilation_cache_dir``) is
    respected.  Programs that compiled in less than ``min_compile_time_secs`` are not
    stored.  Returns the folder in use, or None when disabled.
    """
    if path is None:
        env = os.environ.get(CACHE_ENV)
        if env is not None and env.strip().lower() in _OFF:
            return None
        configured = jax.config.jax_compilation_cache_dir
        if env is None and configured:
            return Path(configured)
        path = env if env is not None else Path.home() / ".cache" / "socbjax" / "jax"
    folder = Path(path).expanduser()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # an unwritable cache must never stop a run
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_secs))
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return folder
