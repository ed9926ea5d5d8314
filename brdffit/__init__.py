"""brdffit: fit analytic BRDF models (JAX + optimistix) to measured reflectance, validate in Mitsuba 3.

The flow is ``load -> Measurement -> fit -> FitResult -> validate``. Fitting runs in float64: the
parts of brdffit that compute with JAX enable ``jax_enable_x64`` when they are first imported
(float32 inputs stay float32; ``brdffit/_x64.py``).
"""

from __future__ import annotations

from . import _interrupt

if _interrupt.is_the_executable():  # the `brdffit` command: Ctrl-C from its first moment is one line, 130
    _interrupt.end_process_on_interrupt()

import importlib  # noqa: E402

from .errors import InputError, UsageError  # noqa: E402
from .grid import ubo_angles, ubo_directions, ubo_pairs  # noqa: E402

__version__ = "0.1.0"

# Everything that needs JAX, matplotlib or Mitsuba loads on first use: `import brdffit` and the
# CLI start without them (``brdffit fit`` draws its figure in a process that never imports JAX),
# and Mitsuba is imported only where rendering happens.
_LAZY = {
    "Measurement": "brdffit.measurement",
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
    "fit_btf_database": "brdffit.btf",
    "ParameterMaps": "brdffit.btf",
    "validate_btf": "brdffit.btf",
    "BTFValidation": "brdffit.btf",
    "scene_usage": "brdffit.scene",
    "render_scene": "brdffit.scene",
    "validate_scene": "brdffit.scene",
    "Usage": "brdffit.scene",
    "explore": "brdffit.explorer",
    "Explorer": "brdffit.explorer",
}
# brdffit.plot is a module: `import brdffit.plot` or `brdffit.plot` after first use (lazy, below)


def __getattr__(name: str):
    if name in ("plot", "models"):  # modules
        return importlib.import_module(f"brdffit.{name}")
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'brdffit' has no attribute {name!r}")


def _register_mitsuba_plugin() -> None:
    # A user who set a Mitsuba variant before `import brdffit` can load scenes with
    # <bsdf type="brdffit"> right away (docs/materials.md#a-fit-in-any-mitsuba-scene); otherwise brdffit.register_mitsuba() does it.
    import sys

    if "mitsuba" in sys.modules:
        from .render.export import register_if_loaded

        register_if_loaded()


_register_mitsuba_plugin()


def __dir__():
    # the public names only (not the helpers this module imports: annotations, importlib)
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
