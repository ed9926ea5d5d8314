"""Persistent compilation cache (SPEC 5): compiled solvers are kept on disk, so a second process
does not compile again.

JAX's own persistent cache, in ``<user cache folder>/jax`` (``platformdirs.user_cache_dir
("brdffit")``: ``~/.cache/brdffit`` on Linux, ``~/Library/Caches/brdffit`` on macOS).
``BRDFFIT_CACHE=DIR`` moves it, ``BRDFFIT_CACHE=off`` disables it. Enabled when
``brdffit.fitting`` is imported (before anything compiles). Every compilation is kept, however
short (JAX keeps only those over 1 s by default; our solvers take 0.2-3 s each).
"""

from __future__ import annotations

import os
from pathlib import Path

_STATE = {"dir": None}


def cache_dir() -> Path | None:
    """Where compiled code is kept, or None when disabled."""
    env = os.environ.get("BRDFFIT_CACHE", "").strip()
    if env.lower() in ("off", "0", "none", "false", "no"):
        return None
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("brdffit")) / "jax"


def enable() -> Path | None:
    """Point JAX's persistent compilation cache at ``cache_dir()`` (idempotent)."""
    import jax

    path = cache_dir()
    if path is None:
        return None
    if _STATE["dir"] == path:
        return path
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # a read-only home: compile every time rather than fail
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _STATE["dir"] = path
    return path


def cache_enabled() -> bool:
    return _STATE["dir"] is not None
