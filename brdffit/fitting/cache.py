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


def _library_model(model) -> bool:
    """A model whose formulas all live in brdffit (a user's own formula is not keyed on disk)."""
    parts = getattr(model, "components", ()) or (model,)
    return all(getattr(c.formula, "__module__", "").startswith("brdffit.") for c in parts)


def _source_hash() -> str:
    """Hash of brdffit's fitting and model sources: a code change invalidates the exports."""
    if "source" not in _STATE:
        import hashlib

        h = hashlib.sha256()
        root = Path(__file__).resolve().parents[1]
        for sub in ("fitting", "models"):
            for f in sorted((root / sub).glob("*.py")):
                h.update(f.name.encode())
                h.update(f.read_bytes())
        _STATE["source"] = h.hexdigest()[:16]
    return _STATE["source"]


def _key_text(key, example) -> str | None:
    import jax

    parts = []
    for k in key:
        if hasattr(k, "param_names") and hasattr(k, "formula"):
            if not _library_model(k):
                return None
            parts.append(f"model={k.name}/{k.channels}/{k.param_names}")
        elif isinstance(k, (str, int, float, bool)) or k is None:
            parts.append(repr(k))
        else:
            return None
    shapes = [(tuple(a.shape), str(a.dtype)) for a in jax.tree_util.tree_leaves(example)]
    return f"{parts}|{shapes}|{jax.tree_util.tree_structure(example)}|jax {jax.__version__}|{_source_hash()}"


def exported(key, build, example):
    """Compiled ``jax.jit(build())`` for ``example``'s shapes; with the cache on, the traced
    program is kept on disk (``jax.export``) and the compiled code in JAX's persistent cache."""
    import hashlib

    import jax

    path = _STATE["dir"]
    text = _key_text(key, example) if path is not None else None
    if text is None:
        return jax.jit(build()).lower(*example).compile()
    file = path / "brdffit-export" / (hashlib.sha256(text.encode()).hexdigest()[:32] + ".bin")
    # The exported program takes the flat list of arrays (our own pytree types, such as
    # problem.Data, are not serialisable); the returned callable takes the original arguments.
    leaves, treedef = jax.tree_util.tree_flatten(example)

    def wrap(compiled_flat):
        return lambda *args: compiled_flat(*jax.tree_util.tree_leaves(args))

    if file.exists():
        try:
            exp = jax.export.deserialize(bytearray(file.read_bytes()))
            return wrap(jax.jit(exp.call).lower(*leaves).compile())
        except Exception:  # a damaged or foreign file: trace again below
            pass
    fn = build()
    jitted = jax.jit(lambda *flat: fn(*jax.tree_util.tree_unflatten(treedef, flat)))
    try:
        exp = jax.export.export(jitted)(*leaves)
        data = exp.serialize()
        file.parent.mkdir(parents=True, exist_ok=True)
        tmp = file.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(data)
        os.replace(tmp, file)  # atomic: concurrent processes write the same bytes
        return wrap(jax.jit(exp.call).lower(*leaves).compile())
    except Exception:  # not exportable (e.g. a custom call without a stable id): no disk copy
        return wrap(jitted.lower(*leaves).compile())
