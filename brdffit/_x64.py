"""Fitting runs in float64: every part of brdffit that computes with JAX imports this module
first, which enables ``jax_enable_x64`` (float32 inputs stay float32).

``import brdffit`` itself imports neither JAX nor matplotlib (the CLI starts without them). The
flag is set when the first part that needs JAX is imported (``brdffit.models``,
``brdffit.measurement``, ``brdffit.io``, ``brdffit.fitting``, ...), before any of them computes;
``tests/test_lazy_imports.py`` checks that every module importing JAX comes after this one.
"""

import gc as _gc

# Importing JAX creates ~10^6 long-lived objects and hardly any garbage: the cyclic collector
# would walk them again and again while they load (~0.08 s CPU). Paused for this import only;
# the caller's setting is restored.
_collecting = _gc.isenabled()
_gc.disable()
try:
    import jax
finally:
    if _collecting:
        _gc.enable()
    del _collecting

jax.config.update("jax_enable_x64", True)
