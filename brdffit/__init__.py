"""brdffit: fit analytic BRDF models (JAX + optimistix) to measured reflectance, validate in Mitsuba 3.

The flow is ``load -> Measurement -> fit -> FitResult -> validate``. Fitting runs in float64:
importing brdffit enables ``jax_enable_x64`` (float32 inputs stay float32).
"""

from __future__ import annotations

import importlib

import jax

jax.config.update("jax_enable_x64", True)

from . import models  # noqa: E402
from .errors import InputError, UsageError  # noqa: E402
from .grid import ubo_angles, ubo_directions, ubo_pairs  # noqa: E402
from .measurement import Measurement  # noqa: E402

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
    "scene_usage": "brdffit.scene",
    "render_scene": "brdffit.scene",
    "validate_scene": "brdffit.scene",
    "Usage": "brdffit.scene",
}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'brdffit' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_LAZY))


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
