"""brdffit: fit analytic BRDF models (JAX + optimistix) to measured reflectance, validate in Mitsuba 3.

The flow is ``load -> Measurement -> fit -> FitResult -> validate``. Fitting runs in float64:
importing brdffit enables ``jax_enable_x64`` (float32 inputs stay float32).
"""

from __future__ import annotations

import gc as _gc
import importlib

# Importing JAX creates ~10^6 long-lived objects and hardly any garbage: the cyclic
# collector would walk them again and again while they load (~0.08 s CPU of every `brdffit`
# command, which imports this package before it can tune the collector). Paused for these
# imports only; the caller's setting is restored.
_collecting = _gc.isenabled()
_gc.disable()
try:
    import jax

    jax.config.update("jax_enable_x64", True)

    from . import models
    from .errors import InputError, UsageError
    from .grid import ubo_angles, ubo_directions, ubo_pairs
    from .measurement import Measurement
finally:
    if _collecting:
        _gc.enable()
    del _collecting

__version__ = "0.1.0"

# Heavier parts load on first use, so that `import brdffit` and the CLI start fast and Mitsuba is
# imported only where rendering happens.
_LAZY = {
    "load": "brdffit.io",
    "save": "brdffit.io",
    "resample": "brdffit.io",
    "albedo": "brdffit.models.albedo",
    "fit": "brdffit.fitting",
    "fit_batch": "brdffit.fitting",
    "FitResult": "brdffit.fitting",
    "compare": "brdffit.fitting",
    "Report": "brdffit.fitting",
    "select": "brdffit.fitting",
    "render_sphere": "brdffit.render",
    "validate": "brdffit.render",
    "Validation": "brdffit.render",
    "mitsuba_bsdf": "brdffit.render.export",
    "register_mitsuba": "brdffit.render.export",
    "evaluated_calls": "brdffit._mitsuba",
    "BTF": "brdffit.btf",
    "load_btf": "brdffit.btf",
    "fit_btf": "brdffit.btf",
    "ParameterMaps": "brdffit.btf",
    "validate_btf": "brdffit.btf",
    "BTFValidation": "brdffit.btf",
    "scene_usage": "brdffit.scene",
    "render_scene": "brdffit.scene",
    "validate_scene": "brdffit.scene",
    "Usage": "brdffit.scene",
}
# brdffit.plot is a module: `import brdffit.plot` or `brdffit.plot` after first use (lazy, below)


def __getattr__(name: str):
    if name == "plot":
        return importlib.import_module("brdffit.plot")
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'brdffit' has no attribute {name!r}")


def _register_mitsuba_plugin() -> None:
    # A user who set a Mitsuba variant before `import brdffit` can load scenes with
    # <bsdf type="brdffit"> right away (SPEC 8); otherwise brdffit.register_mitsuba() does it.
    import sys

    if "mitsuba" in sys.modules:
        from .render.export import register_if_loaded

        register_if_loaded()


_register_mitsuba_plugin()


def __dir__():
    # the public names only (not the helpers this module imports: annotations, importlib, jax)
    return sorted({*__all__, "__version__", "plot"})


__all__ = [
    "InputError",
    "Measurement",
    "UsageError",
    "models",
    "ubo_angles",
    "ubo_directions",
    "ubo_pairs",
    *_LAZY,
]
